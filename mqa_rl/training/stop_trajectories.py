"""The episodes a stop is fitted on: a push policy's never-stopping episodes, every state's stop features and the
measures a stop can minimise (the targets' mean χ, the share of targets a perfect counter misses), kept per level in a
cache that a rerun reads back instead of rolling the episodes out again; and the fixed part of the scenes held out
to score the fit."""

from __future__ import annotations

import hashlib
import io
from pathlib import Path

import torch

from mqa_rl import keys
from mqa_rl.files import load_tensors, write_atomic
from mqa_rl.modules.answering.perceived_count import READING, PerceivedCount
from mqa_rl.modules.stop.learned_stop import FEATURES, stop_features
from mqa_rl.transforms.episode_stats import mean_target_chi, uncountable_share


def padded(x: torch.Tensor, length: int) -> torch.Tensor:
    """``x`` cut or extended with its last row to ``length`` rows (an episode that ended early stays where it was)."""
    pad = length - x.shape[0]
    return torch.cat([x, x[-1:].expand(pad, *x.shape[1:])]) if pad > 0 else x[:length]


def collect_trajectories(env, policy, net, episodes: int, max_pushes: int, reading: PerceivedCount | None = None) -> dict:
    """Never-stopping episodes of ``policy``: features [E, T, F] (with ``reading``'s after the shipped ones), χ and
    the uncountable share [E, T + 1], valid [E, T], scene ids."""
    width = len(FEATURES) + (len(READING) if reading is not None else 0)
    feats, chis, missed, valid, scenes = [], [], [], [], []
    with torch.no_grad():
        for _ in range(episodes):
            rollout = env.rollout(max_pushes + 1, policy, break_when_any_done=True)
            if not bool(rollout[0].get(keys.TARGET_MASK).any()):
                continue                                   # no target (a count of 0): χ undefined
            steps = rollout.shape[0]
            f = stop_features(net, rollout, max_pushes)
            if reading is not None:
                f = torch.cat([f, reading.read(rollout)], -1)
            chi = torch.cat([mean_target_chi(rollout).squeeze(-1), mean_target_chi(rollout["next"][-1:]).squeeze(-1)])
            miss = torch.cat([uncountable_share(rollout), uncountable_share(rollout["next"][-1:])])
            feats.append(padded(f, max_pushes))
            chis.append(padded(chi, max_pushes + 1))
            missed.append(padded(miss, max_pushes + 1))
            valid.append(torch.arange(max_pushes) < min(steps, max_pushes))
            scenes.append(env.base_env.question.scene_id)
    if not feats:
        return {"features": torch.zeros(0, max_pushes, width), "chi": torch.zeros(0, max_pushes + 1),
                "uncountable": torch.zeros(0, max_pushes + 1), "valid": torch.zeros(0, max_pushes, dtype=torch.bool),
                "scenes": []}
    return {"features": torch.stack(feats), "chi": torch.stack(chis), "uncountable": torch.stack(missed),
            "valid": torch.stack(valid), "scenes": scenes}


def held_out(scenes: list[str], fraction: float) -> torch.Tensor:
    """[E] bool: the episodes of a fixed ``fraction`` of the scenes (by a hash of their id)."""
    cut = int(round(fraction * 1000))
    return torch.tensor([int(hashlib.sha256(s.encode()).hexdigest(), 16) % 1000 < cut for s in scenes])


def cached_trajectories(path: Path, meta: dict) -> dict | None:
    """An earlier run's trajectories of the same policy and questions, read as tensors only (a cache in a
    folder a user was handed must not run code), or None."""
    if not path.is_file():
        return None
    saved = load_tensors(path, what="trajectories cache", hint="delete it to collect the trajectories again")
    return saved["data"] if isinstance(saved, dict) and saved.get("meta") == meta else None


def save_trajectories(path: Path, meta: dict, data: dict) -> None:
    """Write one level's trajectories with the ``meta`` that ``cached_trajectories`` matches them by (atomically)."""
    buffer = io.BytesIO()
    torch.save({"meta": meta, "data": data}, buffer)
    write_atomic(path, buffer.getvalue())

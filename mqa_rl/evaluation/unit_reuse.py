"""What an evaluation's finished unit (a policy's episodes at one level) depends on, by content, and reusing one:
a unit is kept only when every input is the same — the dataset's fingerprint (not its path), the questions' settings,
the reward, the kept-frame perception's digest, and for greedy its weights, stopping rule and videos. Anything
changed runs again."""

from __future__ import annotations

from pathlib import Path

import torch
from omegaconf import DictConfig

from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.files import load_tensors
from mqa_rl.modules.answering.perceived_count import file_sha256
from mqa_rl.modules.push.trained_policy import newest_run_checkpoint
from mqa_rl.verified_checkpoint import component_digest


def content_digest(path, what: str, file_name: str | None = None) -> str | None:
    """The SHA-256 of the file ``path`` names (or of ``path/file_name`` for a folder): what a reused unit is keyed
    by, so a file changed at the same path runs its units again. None for no path."""
    if not path:
        return None
    found = Path(path)
    if found.is_dir() and file_name:
        found = found / file_name
    if not found.is_file():
        raise FileNotFoundError(f"{what}={path} names no file" + (f" (nor a folder holding {file_name})" if file_name else "")
                                + f": give an existing {what}, or {what}=null")
    return file_sha256(found)


def episodes_meta(cfg: DictConfig, dataset, level: str, qtypes, max_pushes: int, reward: dict,
                  push_memory: int | None = None, kept_frame: str | None = None) -> dict:
    """What makes two evaluations' episodes the same questions, read the same way (and the same reward): the dataset by
    its content (a dataset regenerated at the same path is another one), and the kept-frame perception's digest
    (its metrics are read by that perception, for every policy)."""
    return {"dataset": dataset_fingerprint(dataset), "split": cfg.split, "seed": int(cfg.seed), "level": level,
            "episodes": int(cfg.episodes_per_level), "max_pushes": max_pushes, "pusher": cfg.pusher,
            "question_types": list(qtypes) if qtypes else None, "reward": reward, "reward_beta": "final", "push_memory": push_memory,
            "kept_frame": kept_frame}


def greedy_identity(cfg: DictConfig) -> dict | None:
    """What makes two evaluations' greedy episodes the same policy: its weights (their digest in the checkpoint's
    integrity record), its stopping rule by content, and the videos asked of it (None when the run has no checkpoint yet)."""
    checkpoint = Path(cfg.checkpoint) if cfg.checkpoint else newest_run_checkpoint(cfg.run)
    if checkpoint is None:
        return None
    return {"weights": component_digest(checkpoint, "policy"), "stop_margin": cfg.stop_margin,
            "stop_critic": content_digest(cfg.stop_critic, "stop_critic", "stop_critic.pt"),
            "video_episodes": int(cfg.video_episodes), "video_format": cfg.video_format}


def reuse_episodes(folder, name: str, meta: dict, needs: tuple[str, ...] = ()) -> dict[str, torch.Tensor] | None:
    """The per-episode metrics of policy ``name`` from an earlier evaluation (or this one, killed), if on the same
    questions and holding the metrics ``needs`` names (a kept frame's, which an evaluation without one did not record)."""
    path = Path(folder) / "episodes" / f"{name}_{meta['level']}.pt"
    if not path.is_file():
        return None
    saved = load_tensors(path, what="baseline episodes file", hint="delete it to evaluate again")
    # the reward is checked below; the paper's random never reads the action mask, so PushMemory leaves it alone
    ignored = ("reward", "push_memory") if name == "random" else ("reward",)
    same = {k: v for k, v in meta.items() if k not in ignored}
    if {k: saved["meta"].get(k) for k in same} != same:
        print(f"  {path}: other questions or settings, not reused")
        return None
    metrics = dict(saved["metrics"])
    lacking = [k for k in needs if k not in metrics]
    if lacking:
        print(f"  {path}: no {', '.join(lacking)} (run without kept_frame=), not reused")
        return None
    if saved["meta"].get("reward") != meta["reward"]:   # another reward config: its rewards don't compare
        metrics = {k: v for k, v in metrics.items() if k != "reward" and not k.startswith("term/")}
    print(f"  {name}: reused {path}")
    return metrics

"""Run whole episodes of a policy on an env with ``EpisodeStats`` and collect their metrics."""

from __future__ import annotations

from collections.abc import Callable

import torch
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from mqa_rl.evaluation.episode_metrics import FINAL_KEYS, episode_metrics, idle_pushes, kept_frame_metrics
from mqa_rl.modules.answering.kept_frame import episode_states


def run_episodes(env, policy, episodes: int, *, max_pushes: int, simple_threshold: float = 0.2,
                 on_episode: Callable[[int, TensorDictBase], None] | None = None, keeper=None) -> dict[str, torch.Tensor]:
    """``episodes`` rollouts (each to its end) under the policy's deterministic mode; metrics [episodes],
    with ``scene``: each episode's pile (its index in the dataset's scenes), for intervals by scene, and
    ``idle_pushes``: its pushes that moved nothing.

    ``keeper`` (a ``FrameKeeper``): also what the frame it keeps of each episode holds (the I_stop of a system that
    answers from it): ``counter_kept``, ``countable_gain_kept``, ``chi_kept``, ``hidden_kept`` (``kept_frame_metrics``).
    ``on_episode(i, rollout)`` sees each rollout (e.g. to write a video). Seed the env beforehand for
    the same questions every time.
    """
    finals, scenes, idle, kept = [], [], [], []
    scene_index = {s.id: i for i, s in enumerate(env.base_env.dataset.scenes)}
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        for i in range(episodes):
            rollout = env.rollout(max_pushes + 1, policy, break_when_any_done=True)
            if not bool(rollout["next", "done"][-1].item()):
                raise RuntimeError(f"episode {i} did not end within {max_pushes + 1} steps: is the env's "
                                   f"max_pushes larger than {max_pushes}?")
            finals.append(rollout["next"][-1].select(*FINAL_KEYS, strict=False))
            scenes.append(scene_index[env.base_env.question.scene_id])
            idle.append(idle_pushes(rollout))
            if keeper is not None:
                states = episode_states(rollout)
                kept.append(kept_frame_metrics(states[0], states[keeper.choose(states)]))
            if on_episode is not None:
                on_episode(i, rollout)
    out = {**episode_metrics(torch.stack(finals), simple_threshold), "scene": torch.tensor(scenes, dtype=torch.int64),
           "idle_pushes": torch.stack(idle)}
    if keeper is None:
        return out
    return {**out, **{k: torch.stack([m[k] for m in kept]) for k in kept[0]}}

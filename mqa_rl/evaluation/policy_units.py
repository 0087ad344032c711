"""A policy's evaluation episodes on one level (a *unit*), run here or on Ray actors (``recipes/evaluate_policy.py``):
greedy (the run under evaluation) or a system of the registry that needs no run (``setup["systems"]``: id -> spec).

A unit seeds its env before its episodes, so it gives the same episodes whichever process runs it and after
whichever other unit: the local and the Ray backends report the same figures. Each process keeps one env
per level and reuses it across the units it runs.
"""

from __future__ import annotations

from pathlib import Path

import torch

from mqa_rl.collectors.ray_pool import RayPool, ray_session
from mqa_rl.envs.qmap_overlay import qmap_episode_frames
from mqa_rl.evaluation.rollouts import run_episodes
from mqa_rl.modules.answering.kept_frame import FrameKeeper
from mqa_rl.modules.frozen_policies import make_frozen_policy
from mqa_rl.modules.push.random_policy import RandomMQAPolicy
from mqa_rl.modules.push.trained_policy import load_greedy
from mqa_rl.modules.stop.learned_stop import LearnedStop
from mqa_rl.modules.stop.stop_margin import StopMargin
from mqa_rl.transforms.beta import trained_counter
from mqa_rl.transforms.mqa_env import make_mqa_env

# The policies a unit runs beside greedy: the registry's systems that need no run (their specs travel in the setup).
REFERENCE_KINDS = ("random", "random_masked", "none", "privileged")

_ENVS: dict = {}            # this process's env per level: a unit reuses it (local: one process; ray: per actor)


def unit_env(setup: dict, level: str):
    if level not in _ENVS:
        _ENVS[level] = make_mqa_env(setup["dataset"], setup["reward"], trained_counter(setup["reward"]),
                                    episode_stats=True, split=setup["split"],
                                    difficulties=[level], question_types=setup["qtypes"], max_pushes=setup["max_pushes"],
                                    pusher=setup["pusher"], push_memory=setup["push_memory"],
                                    **setup.get("frames", {}))
    return _ENVS[level]


def close_envs() -> None:
    while _ENVS:
        _ENVS.popitem()[1].close()


def evaluate_unit(setup: dict, level: str, name: str) -> tuple[dict, list]:
    """One policy's episodes on one level: (per-episode metrics, video frames of the first greedy episodes).
    The env is seeded before the unit, so a unit gives the same episodes whichever process runs it and after
    whichever other unit (local and Ray alike)."""
    env = unit_env(setup, level)
    env.base_env.set_seed(setup["seed"])                # the same questions for every policy
    max_pushes, videos, on_episode = setup["max_pushes"], [], None
    if name == "greedy":
        policy, _, _ = load_greedy(Path(setup["run"]), setup["checkpoint"], env)
        if setup["stop_margin"] is not None:
            policy = StopMargin(policy, float(setup["stop_margin"]))
        if setup["stop_critic"] is not None:
            policy = LearnedStop.from_file(policy, setup["stop_critic"], max_pushes, setup["push_memory"])

        def on_episode(i, rollout):
            if i < setup["video_episodes"]:
                videos.append(qmap_episode_frames(rollout, env.base_env.camera, env.base_env.question.text))
    elif name in setup["systems"]:
        spec = setup["systems"][name]
        if spec["kind"] in ("random", "random_masked"):        # seeded per unit: the same draws on either backend
            policy = RandomMQAPolicy(max_pushes, seed=setup["seed"], masked=spec["kind"] == "random_masked")
        else:
            policy, _ = make_frozen_policy(spec, env.base_env, max_pushes)
    else:
        raise ValueError(f"unknown policy {name!r}; choose among greedy, {', '.join(setup['systems'])}")
    keeper = FrameKeeper.from_file(setup["kept_frame"], env.base_env.dataset, policy) if setup.get("kept_frame") else None
    metrics = run_episodes(env, policy, setup["episodes"], max_pushes=max_pushes, simple_threshold=setup["threshold"],
                           on_episode=on_episode, keeper=keeper)
    return metrics, videos


def _ray_unit(task: tuple[dict, str, str]) -> tuple[tuple[str, str], tuple[dict, list]]:
    """A unit on a Ray actor, tagged with its (level, policy): results come back as they finish."""
    torch.set_num_threads(1)
    setup, level, name = task
    return (level, name), evaluate_unit(setup, level, name)


def run_units(setup: dict, units: list[tuple[str, str]], backend: str, ray_address: str | None, workers: int):
    """Yield ((level, policy), (metrics, videos)) for every unit: in this process one after another (local),
    or on ``workers`` Ray actors as they finish (a unit whose actor dies runs again on another)."""
    if backend == "local":
        for level, name in units:
            yield (level, name), evaluate_unit(setup, level, name)
        return
    with ray_session(ray_address, num_cpus=workers):
        pool = RayPool(max(1, min(workers, len(units))))
        try:
            yield from pool.imap_unordered(_ray_unit, [(setup, level, name) for level, name in units])
        finally:
            pool.terminate()

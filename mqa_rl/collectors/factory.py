"""``make_collector``: the MQA env with its reward stack in 1 or N workers, from the ``collector`` config.

    kind: single        Collector in this process (the env steps between updates)
    kind: multi_sync    MultiSyncCollector, ``num_workers`` processes, one batch from all of them
    kind: multi_async   MultiAsyncCollector, workers keep collecting while the learner updates

The env factory is ``mqa_rl.transforms.mqa_env.make_mqa_env`` (module level, so spawned workers can
import it). The β step counter is a shared-memory tensor handed to every worker through
``create_env_kwargs`` (a closure would give each worker a frozen copy). A ``ray`` kind
(``torchrl.collectors.distributed.RayCollector``) can be added here without touching the recipe.

Use ``running(collector)`` around the loop: it shuts the workers down on any exit, including an
exception or Ctrl-C, so no worker process outlives the run.
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping

import torch
from torchrl.collectors import BaseCollector, Collector, MultiAsyncCollector, MultiSyncCollector

from mqa_rl.transforms.mqa_env import make_mqa_env

KINDS = ("single", "multi_sync", "multi_async")


def make_collector(cfg: Mapping, policy, env_kwargs: Mapping, *, total_frames: int, init_random_frames: int = 0,
                   seed: int | None = None) -> BaseCollector:
    """A collector of ``policy`` on ``make_mqa_env(**env_kwargs)``; ``env_kwargs`` may hold the shared counter."""
    kind = cfg.get("kind", "single")
    workers = int(cfg.get("num_workers", 1))
    frames_per_batch = int(cfg["frames_per_batch"])
    if kind not in KINDS:
        raise ValueError(f"collector.kind={kind!r}; choose one of {KINDS}")
    if workers < 1 or (kind == "single" and workers != 1):
        raise ValueError(f"collector.num_workers={workers}: 'single' runs exactly 1 env, the multi kinds ≥ 1")
    if frames_per_batch % workers or total_frames % frames_per_batch:
        raise ValueError(f"collector.frames_per_batch={frames_per_batch} must be a multiple of num_workers={workers}, "
                         f"and total frames {total_frames} a multiple of frames_per_batch")
    common = dict(frames_per_batch=frames_per_batch, total_frames=total_frames, init_random_frames=init_random_frames,
                  device="cpu", storing_device="cpu", auto_register_policy_transforms=False)
    if kind == "single":
        coll = Collector(make_mqa_env, policy, create_env_kwargs=dict(env_kwargs), **common)
    else:
        cls = MultiSyncCollector if kind == "multi_sync" else MultiAsyncCollector
        coll = cls([make_mqa_env] * workers, policy, create_env_kwargs=[dict(env_kwargs)] * workers,
                   num_threads=int(cfg.get("learner_threads") or torch.get_num_threads()), num_sub_threads=1, **common)
    if seed is not None:
        coll.set_seed(seed)
    return coll


@contextlib.contextmanager
def running(collector: BaseCollector):
    """Yield ``collector``; shut it down however the block ends (error, Ctrl-C, SIGTERM)."""
    try:
        yield collector
    finally:
        with contextlib.suppress(Exception):
            collector.shutdown()

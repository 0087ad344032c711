"""``make_collector``: the MQA env with its reward stack in 1 or N workers, from the ``collector`` config.

    kind: single        Collector in this process (the env steps between updates)
    kind: multi_sync    MultiSyncCollector, ``num_workers`` processes, one batch from all of them
    kind: multi_async   MultiAsyncCollector, workers keep collecting while the learner updates
    kind: ray           TorchRL's RayCollector: ``num_workers`` actors of one CPU on the Ray cluster at
                        ``ray_address`` (or a local Ray), one batch from all of them, weights pushed after
                        every batch as the local kinds do

The env factory is ``mqa_rl.transforms.mqa_env.make_mqa_env`` (module level, so spawned workers can
import it). The β step counter is a shared-memory tensor handed to every worker through
``create_env_kwargs`` (a closure would give each worker a frozen copy). Ray copies every argument, so on
Ray the counter is set in each actor's env after every batch instead (``share_train_steps``).

Use ``running(collector)`` around the loop: it shuts the workers down on any exit, including an
exception or Ctrl-C, so no worker process outlives the run.
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping

import torch
from torchrl.collectors import BaseCollector, Collector, MultiAsyncCollector, MultiSyncCollector

from mqa_rl.collectors.ray_pool import check_ray_address, import_ray, ray_init_options
from mqa_rl.transforms.beta import BetaSchedule
from mqa_rl.transforms.factory import make_reward_transform
from mqa_rl.transforms.mqa_env import make_mqa_env

KINDS = ("single", "multi_sync", "multi_async", "ray")


def check_collector(cfg: Mapping, ray_address: str | None = None) -> None:
    """The ``collector`` config's errors, for a recipe to raise before it writes anything: an unknown kind, a worker
    count the kind cannot run, and for ``ray`` a ``ray.address`` where no Ray head answers (TorchRL's RayCollector
    calls ``ray.init`` itself, which retries such an address for minutes: ``check_ray_address``)."""
    kind = cfg.get("kind", "single")
    workers = int(cfg.get("num_workers", 1))
    if kind not in KINDS:
        raise ValueError(f"collector.kind={kind!r}; choose one of {KINDS}")
    if workers < 1 or (kind == "single" and workers != 1):
        raise ValueError(f"collector.num_workers={workers}: 'single' runs exactly 1 env, the multi kinds and ray ≥ 1")
    if kind == "ray":
        import_ray()
        check_ray_address(ray_address)


def make_collector(cfg: Mapping, policy, env_kwargs: Mapping, *, total_frames: int, init_random_frames: int = 0,
                   seed: int | None = None, ray_address: str | None = None) -> BaseCollector:
    """A collector of ``policy`` on ``make_mqa_env(**env_kwargs)``; ``env_kwargs`` may hold the shared counter."""
    check_collector(cfg, ray_address)
    kind = cfg.get("kind", "single")
    workers = int(cfg.get("num_workers", 1))
    frames_per_batch = int(cfg["frames_per_batch"])
    if frames_per_batch % workers or total_frames % frames_per_batch:
        raise ValueError(f"collector.frames_per_batch={frames_per_batch} must be a multiple of num_workers={workers}, "
                         f"and total frames {total_frames} a multiple of frames_per_batch")
    common = dict(frames_per_batch=frames_per_batch, total_frames=total_frames, init_random_frames=init_random_frames,
                  device="cpu", storing_device="cpu", auto_register_policy_transforms=False)
    if kind == "single":
        coll = Collector(make_mqa_env, policy, create_env_kwargs=dict(env_kwargs), **common)
    elif kind == "ray":
        from torchrl.collectors.distributed import RayCollector

        # a fresh dict per call: RayCollector adds its own keys to the one it is given
        inner = dict(create_env_kwargs={k: v for k, v in env_kwargs.items() if k != "counter"},
                     auto_register_policy_transforms=False, init_random_frames=init_random_frames)
        coll = RayCollector(make_mqa_env, policy, frames_per_batch=frames_per_batch, total_frames=total_frames,
                            num_collectors=workers, sync=True, collector_kwargs=inner, device="cpu", storing_device="cpu",
                            ray_init_config=ray_init_options(ray_address, workers),
                            remote_configs={"num_cpus": 1, "memory": 3 * 1024 ** 3})
        coll.update_policy_weights_(policy)      # the first push: lazily sets up the weight-sync group
        if env_kwargs.get("reward") is not None:
            stack = make_reward_transform(env_kwargs["reward"], push_length=1.0)
            coll._mqa_beta_index = next((i for i, t in enumerate(stack) if isinstance(t, BetaSchedule)), None)
    else:
        cls = MultiSyncCollector if kind == "multi_sync" else MultiAsyncCollector
        coll = cls([make_mqa_env] * workers, policy, create_env_kwargs=[dict(env_kwargs)] * workers,
                   num_threads=int(cfg.get("learner_threads") or torch.get_num_threads()), num_sub_threads=1, **common)
    if seed is not None:
        coll.set_seed(seed)
    return coll


def share_train_steps(collector: BaseCollector, steps: int) -> None:
    """Tell the collector's envs how many training steps were taken (β's S_n). The local kinds share the
    counter's memory already; Ray's actors hold copies, so each actor's ``BetaSchedule`` is set here (its
    place in the env's transforms is the one ``make_reward_transform`` gives it: the stack comes first)."""
    beta = getattr(collector, "_mqa_beta_index", None)
    if beta is not None:
        collector.map_fn(f"env.transform[{beta}].set_train_steps", [(int(steps),)] * collector.num_collectors)


@contextlib.contextmanager
def running(collector: BaseCollector):
    """Yield ``collector``; shut it down however the block ends (error, Ctrl-C, SIGTERM)."""
    try:
        yield collector
    finally:
        with contextlib.suppress(Exception):
            collector.shutdown()

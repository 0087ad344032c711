"""SapienBinEnv speed: push step (median / p90 per level), the floor (the same physics steps plus one
raw render, no wrapper work), reset, construction in a fresh process, MultiSyncCollector throughput.

    python benchmarks/env_step.py --dataset data/mqa [--pushes 60] [--skip-collectors]

Goals: hard step ≤ 150 ms median, step / floor ≤ 1.3, reset ≤ 150 ms,
2 collector workers ≥ 1.7 × 1 worker.
"""

from __future__ import annotations

import argparse
import functools
import subprocess
import sys
import time

import numpy as np
import sapien
import torch

from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv


class PhysicsClock:
    """Accumulates wall time spent inside ``sapien.Scene.step``."""

    def __init__(self):
        self.total = 0.0
        self._orig = sapien.Scene.step

        def timed(scene, *a, **k):
            t = time.perf_counter()
            self._orig(scene, *a, **k)
            self.total += time.perf_counter() - t

        sapien.Scene.step = timed


def raw_render(env) -> float:
    t = time.perf_counter()
    env.world.scene.update_render()
    cam = env.world.camera
    cam.take_picture()
    for name in ("Color", "Position", "Segmentation"):
        cam.get_picture(name)
    return time.perf_counter() - t


def bench_level(dataset: str, level: str, pushes: int, seed: int, clock: PhysicsClock) -> dict:
    env = SapienBinEnv(dataset, split=None, difficulties=[level], seed=seed, max_pushes=10)
    rng = np.random.default_rng(seed)
    td = env.reset()
    raw_render(env)
    steps, floors, resets = [], [], []
    while len(steps) < pushes:
        td["action"] = torch.tensor(int(rng.integers(actions.NUM_PUSHES)))
        clock.total = 0.0
        t = time.perf_counter()
        out = env.step(td)
        steps.append(time.perf_counter() - t)
        floors.append(clock.total + raw_render(env))
        if out["next", "done"].item():
            t = time.perf_counter()
            td = env.reset()
            resets.append(time.perf_counter() - t)
        else:
            td = out["next"].clone()
    for _ in range(5):
        t = time.perf_counter()
        env.reset()
        resets.append(time.perf_counter() - t)
    s, f = np.array(steps) * 1e3, np.array(floors) * 1e3
    return {"level": level, "median": np.median(s), "p90": np.percentile(s, 90), "floor": np.median(f),
            "ratio": np.median(s / f), "reset": np.median(resets) * 1e3}


def bench_construction(dataset: str) -> tuple[float, float]:
    code = ("import time; t=time.perf_counter(); from mqa_rl.envs.sapien_bin import SapienBinEnv; "
            f"e=SapienBinEnv({dataset!r}); t1=time.perf_counter(); e.reset(); t2=time.perf_counter(); "
            "print(t1-t, t2-t1)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    return float(out[-2]), float(out[-1])


def bench_collector(dataset: str, workers: int, frames: int = 40) -> float:
    from torchrl.collectors import MultiSyncCollector

    from mqa_rl.modules.push.random_policy import RandomMQAPolicy

    make = functools.partial(SapienBinEnv, dataset, split=None, difficulties=["hard"], max_pushes=10)
    coll = MultiSyncCollector([make] * workers, RandomMQAPolicy(10, seed=0), frames_per_batch=10 * workers,
                              total_frames=-1, auto_register_policy_transforms=False)
    try:
        it = iter(coll)
        next(it)                      # warm-up: worker start, shader compile
        t, n = time.perf_counter(), 0
        while n < frames:
            n += next(it).numel()
        return n / (time.perf_counter() - t)
    finally:
        coll.shutdown()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--dataset", default="data/mqa")
    ap.add_argument("--pushes", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip-collectors", action="store_true")
    args = ap.parse_args()
    clock = PhysicsClock()
    print(f"{'level':<8}{'median ms':>10}{'p90 ms':>8}{'floor ms':>10}{'step/floor':>11}{'reset ms':>10}")
    for level in ("easy", "medium", "hard"):
        r = bench_level(args.dataset, level, args.pushes, args.seed, clock)
        print(f"{r['level']:<8}{r['median']:>10.0f}{r['p90']:>8.0f}{r['floor']:>10.0f}{r['ratio']:>11.2f}{r['reset']:>10.0f}")
    build, first_reset = bench_construction(args.dataset)
    print(f"fresh process: import + construction {build:.2f} s, first reset (shader compile) {first_reset:.2f} s")
    if not args.skip_collectors:
        one = bench_collector(args.dataset, 1)
        two = bench_collector(args.dataset, 2)
        print(f"MultiSyncCollector (hard, random policy): 1 worker {one:.2f} steps/s, 2 workers {two:.2f} steps/s "
              f"({two / one:.2f}x)")


if __name__ == "__main__":
    main()

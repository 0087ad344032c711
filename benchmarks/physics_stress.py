"""Physics robustness: many random pushes over hard scenes; counts escapes (an object whose centre
leaves the bin or drops below the floor), NaN poses, and the largest object speed seen at any time
(sampled every 4 physics steps, pushes and settling included).

    python benchmarks/physics_stress.py --dataset data/mqa [--pushes 2000]

Goal (issue 3): 0 escapes, 0 NaN.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import sapien
import torch

from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--dataset", default="data/mqa")
    ap.add_argument("--pushes", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    env = SapienBinEnv(args.dataset, split=None, difficulties=["hard"], seed=args.seed, max_pushes=10)
    peak = {"speed": 0.0, "n": 0}
    orig_step = sapien.Scene.step

    def sampled_step(scene, *a, **k):
        orig_step(scene, *a, **k)
        peak["n"] += 1
        if peak["n"] % 4 == 0 and env.world is not None:
            peak["speed"] = max(peak["speed"], float(np.nan_to_num(env.world.speeds(), nan=np.inf).max()))

    sapien.Scene.step = sampled_step
    rng = np.random.default_rng(args.seed)
    escapes, nans, episodes = 0, 0, 0
    worst = None
    t0 = time.perf_counter()
    td = env.reset()
    for k in range(args.pushes):
        td["action"] = torch.tensor(int(rng.integers(actions.NUM_PUSHES)))
        out = env.step(td)
        poses = env.world.poses()
        if not np.isfinite(poses).all():
            nans += 1
        out_of_bin = ~env.world.bin.inside(poses[:, :3], margin=-0.005) | (poses[:, 2] < -0.005)
        if out_of_bin.any():
            escapes += int(out_of_bin.sum())
            worst = (env.question.scene_id, k, poses[out_of_bin][:, :3].round(3).tolist())
        if out["next", "done"].item():
            episodes += 1
            td = env.reset()
        else:
            td = out["next"].clone()
        if (k + 1) % 250 == 0:
            print(f"  {k + 1} pushes, {time.perf_counter() - t0:.0f} s: escapes {escapes}, NaN {nans}, "
                  f"largest object speed {peak['speed']:.3f} m/s", flush=True)
    print(f"{args.pushes} random pushes on hard scenes ({episodes} episodes, {time.perf_counter() - t0:.0f} s): "
          f"escapes {escapes}, NaN {nans}, largest object speed {peak['speed']:.3f} m/s")
    if worst:
        print(f"last escape: scene {worst[0]}, push {worst[1]}, positions {worst[2]}")


if __name__ == "__main__":
    main()

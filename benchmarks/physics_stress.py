"""Physics robustness: many random pushes over hard scenes; counts escapes (an object whose centre
leaves the bin or drops below the floor), NaN poses, and the largest object speed seen at any time
(sampled every 4 physics steps, pushes and settling included). With ``--pusher arm`` it also counts
pushes where an arm part other than the stick touched something, the objects that escaped in those
pushes (knocked out by the arm's links), and unreachable pushes.

    python benchmarks/physics_stress.py --dataset data/mqa [--pushes 2000] [--pusher arm]

Goal: 0 escapes, 0 NaN.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import sapien
import torch

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.sim.pushers import PUSHER_NAMES


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--dataset", default="data/mqa")
    ap.add_argument("--pushes", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pusher", default="finger", choices=PUSHER_NAMES)
    args = ap.parse_args()
    env = SapienBinEnv(args.dataset, split=None, difficulties=["hard"], seed=args.seed, max_pushes=10, pusher=args.pusher)
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
    arm_hits, by_arm, unreachable = 0, 0, 0
    escaped = set()                     # (episode, object index): an escaped object counts once here
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
        hit = bool(out["next", *keys.ARM_COLLISION].item())
        arm_hits += hit
        by_arm += int(out_of_bin.sum()) if hit else 0
        unreachable += bool(out["next", *keys.PUSH_UNREACHABLE].item())
        escaped.update((episodes, int(i)) for i in np.flatnonzero(out_of_bin))
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
                  f"largest object speed {peak['speed']:.3f} m/s; arm contacts {arm_hits}, escapes in those {by_arm}, "
                  f"unreachable {unreachable}", flush=True)
    print(f"{args.pushes} random pushes ({args.pusher}) on hard scenes ({episodes} episodes, {time.perf_counter() - t0:.0f} s): "
          f"escapes {escapes} (objects out after a push, summed over pushes; {len(escaped)} distinct objects), NaN {nans}, "
          f"largest object speed {peak['speed']:.3f} m/s; pushes with an arm part "
          f"(not the stick) touching something {arm_hits}, objects escaped in those {by_arm}; unreachable pushes {unreachable}")
    if worst:
        print(f"last escape: scene {worst[0]}, push {worst[1]}, positions {worst[2]}")


if __name__ == "__main__":
    main()

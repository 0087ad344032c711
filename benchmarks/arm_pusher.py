"""The arm pusher measured against the finger.

    python benchmarks/arm_pusher.py reach                       # IK over the 28 x 28 x 8 grid pushes (~15 min)
    python benchmarks/arm_pusher.py steps --dataset data/mqa    # finger vs arm: step time, tip error (same actions)
    python benchmarks/arm_pusher.py transfer --dataset data/mqa  # random baseline with each pusher

* ``reach``: every grid push (cell centre → the start point at a surface height, 8 directions, the env's
  push length) planned by inverse kinematics without physics; the fraction fully reachable, per height
  (the floor and the top of a 35 cm pile by default).
* ``steps``: the same random push sequence on each level with the finger and with the arm, in one
  process: step time (median / p90), and for the arm the tip's distance to the push line (mean / max
  over pushes of the per-push mean and max), unreachable pushes and arm-part contacts.
* ``transfer``: target χ reduction (mean target overlap at reset minus at the end) of the random
  baseline on the test split's COUNTING questions, with each pusher (the same seeded actions). For a
  trained policy: ``recipes/evaluate_policy.py run=<train_dqn run> pusher=finger`` and ``pusher=arm``
  (its ``chi_change`` column).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.modules.push.random_policy import RandomMQAPolicy
from mqa_rl.sim.arm_pusher import ArmPusher
from mqa_rl.sim.geometry import BinSpec, CameraSpec
from mqa_rl.sim.scene import build_world

LEVELS = ("easy", "medium", "hard")


def reach(heights: list[float]) -> None:
    world = build_world([], np.zeros((0, 7)), bin_spec=BinSpec())
    arm = ArmPusher()
    arm.attach(world)
    camera = CameraSpec()
    length = camera.floor_width() / 4
    for h in heights:
        t0 = time.perf_counter()
        ok = np.zeros((actions.DIRECTIONS, actions.GRID, actions.GRID), bool)
        for row in range(actions.GRID):
            for col in range(actions.GRID):
                uv = actions.cell_centre_uv(row, col, camera.height, camera.width)
                start = camera.unproject(uv, np.float64(camera.distance - h))
                for d in range(actions.DIRECTIONS):
                    ok[d, row, col] = arm.plan_push(world.bin, start, actions.direction_xy(d), length).reachable
        worst = np.argwhere(~ok)[:5].tolist()
        print(f"surface {h:.2f} m: {ok.mean():.4f} of {ok.size} grid pushes reachable "
              f"({time.perf_counter() - t0:.0f} s); first unreachable (direction, row, col): {worst}", flush=True)


def steps(dataset: str, pushes: int, seed: int) -> None:
    print(f"{'level':<8}{'finger ms':>10}{'p90':>6}{'arm ms':>8}{'p90':>6}{'arm/finger':>11}"
          f"{'tip err mean/max mm':>22}{'worst push max mm':>19}{'unreach':>8}{'arm hit':>8}")
    for level in LEVELS:
        rows = {}
        for pusher in ("finger", "arm"):
            env = SapienBinEnv(dataset, split=None, difficulties=[level], seed=seed, max_pushes=10, pusher=pusher)
            rng = np.random.default_rng(seed)
            td = env.reset()
            times, err, unreach, hits = [], [], 0, 0
            while len(times) < pushes:
                td[keys.ACTION] = torch.tensor(int(rng.integers(actions.NUM_PUSHES)))
                t = time.perf_counter()
                out = env.step(td)["next"]
                times.append(time.perf_counter() - t)
                err.append(out[keys.TIP_ERROR].numpy())
                unreach += bool(out[keys.PUSH_UNREACHABLE].item())
                hits += bool(out[keys.ARM_COLLISION].item())
                td = env.reset() if out["done"].item() else out.clone()
            t = np.array(times) * 1e3
            rows[pusher] = (np.median(t), np.percentile(t, 90), np.array(err) * 1e3, unreach, hits)
        f, a = rows["finger"], rows["arm"]
        e = a[2]
        print(f"{level:<8}{f[0]:>10.0f}{f[1]:>6.0f}{a[0]:>8.0f}{a[1]:>6.0f}{a[0] / f[0]:>11.2f}"
              f"{e[:, 0].mean():>14.1f} / {e[:, 1].mean():<5.1f}{e[:, 1].max():>19.1f}{a[3]:>8d}{a[4]:>8d}", flush=True)


def transfer(dataset: str, episodes: int, seed: int) -> None:
    for pusher in ("finger", "arm"):
        env = SapienBinEnv(dataset, split="test", question_types=["counting"], seed=seed, max_pushes=10, pusher=pusher)
        pol = RandomMQAPolicy(env.max_pushes, seed=seed)
        qs = env.questions[:: max(len(env.questions) // episodes, 1)][:episodes]
        reductions, t0 = [], time.perf_counter()
        for q in qs:
            td = env.reset(question_id=q.id)
            chi0 = _target_overlap(td)
            with torch.no_grad():
                while True:
                    out = env.step(pol(td.clone()))["next"]
                    if out["done"].item():
                        break
                    td = out.clone()
            if not np.isnan(chi0):
                reductions.append(chi0 - _target_overlap(out))
        print(f"{pusher:<7} random baseline: target χ reduction {np.mean(reductions):+.4f} ± {np.std(reductions) / np.sqrt(len(reductions)):.4f} "
              f"over {len(reductions)} test episodes ({time.perf_counter() - t0:.0f} s)", flush=True)


def _target_overlap(td) -> float:
    mask = td[keys.TARGET_MASK]
    return float(td[keys.OVERLAP][mask].mean()) if mask.any() else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=("reach", "steps", "transfer"))
    ap.add_argument("--dataset", default="data/mqa")
    ap.add_argument("--heights", type=float, nargs="+", default=[0.0, 0.35])
    ap.add_argument("--pushes", type=int, default=30)
    ap.add_argument("--episodes", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.what == "reach":
        reach(args.heights)
    elif args.what == "steps":
        steps(args.dataset, args.pushes, args.seed)
    else:
        transfer(args.dataset, args.episodes, args.seed)


if __name__ == "__main__":
    main()

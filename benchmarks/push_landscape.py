"""How much does the exact push matter? The value landscape around the image teacher's push.

From states the image teacher (``PrivilegedPushPolicy(order="visible_first", geometry="visible")``,
the target of the demonstration runs) reaches on training questions, every candidate push is
simulated on a copy of the scene (``SapienBinEnv.preview``: the episode is untouched) and scored by
the change of the question's targets' mean hidden fraction χ (− reveals). Candidates per state:
the teacher's push; the 7 other directions from its start cell; its direction from the 8
neighbouring cells; ``--random`` pushes drawn from the action mask (what the paper's random does).
Why: imitation students picked the teacher's cell and direction rarely (≤ 0.09) and did not beat
random; this says whether a near miss is worth anything, and how much a one-step lookahead over
cheap candidates could gain over the teacher.

    python benchmarks/push_landscape.py --states 30        # medium + hard training questions, ~10 min on 2 cores

Prints, per candidate group: mean Δχ over pushes with a 95 % CI over states (pushes of one state are
correlated), the fraction revealing (Δχ < −0.05) and covering (> +0.05), and the mean of each state's
best push in the group (a lookahead over that group).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.evaluation.episode_metrics import mean_ci95
from mqa_rl.modules.privileged_policy import PrivilegedPushPolicy


def targets_chi(m: dict, target: np.ndarray) -> float:
    """Mean hidden fraction χ of the targets in a ``measure()`` / ``preview()`` result."""
    return float(m["overlap"][target].mean())


def candidates(teacher_push: int, mask: np.ndarray, rng: np.random.Generator, n_random: int) -> dict[str, list[int]]:
    d, r, c = actions.decode(teacher_push)
    return {
        "teacher": [teacher_push],
        "same cell, other directions": [actions.encode(k, r, c) for k in range(actions.DIRECTIONS) if k != d],
        "same direction, neighbour cells": [actions.encode(d, r + dr, c + dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                                               if (dr or dc) and 0 <= r + dr < actions.GRID and 0 <= c + dc < actions.GRID],
        "random (action mask)": [int(a) for a in rng.choice(np.flatnonzero(mask), n_random, replace=False)],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default="data/mqa")
    p.add_argument("--states", type=int, default=30)
    p.add_argument("--levels", nargs="+", default=["medium", "hard"], choices=["easy", "medium", "hard"])
    p.add_argument("--random", type=int, default=8, help="random candidate pushes per state")
    p.add_argument("--max-teacher-pushes", type=int, default=2,
                   help="the teacher first makes 0..this many pushes, so later states of its episodes count too")
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args()

    env = SapienBinEnv(args.dataset, split="train", seed=args.seed, max_pushes=10, image_size=224,
                       difficulties=args.levels, question_types=["counting"])
    teacher = PrivilegedPushPolicy(env, lookahead=1, order="visible_first", geometry="visible")
    rng = np.random.default_rng(args.seed)
    rows: list[dict[str, np.ndarray]] = []
    start = time.perf_counter()
    while len(rows) < args.states:
        td = env.reset()
        push = teacher.choose()
        for _ in range(int(rng.integers(0, args.max_teacher_pushes + 1))):
            if push == actions.STOP:
                break
            td[keys.ACTION] = torch.tensor(push)
            td = env.step(td)["next"]
            push = teacher.choose()
        if push == actions.STOP or bool(td["done"].item()):
            continue            # a state the teacher would stop in has no push to compare with
        gt = env.ground_truth()
        before = targets_chi(gt, gt["target"])
        mask = td[keys.ACTION_MASK][: actions.NUM_PUSHES].numpy()
        rows.append({name: np.array([targets_chi(env.preview(a), gt["target"]) - before for a in acts])
                     for name, acts in candidates(push, mask, rng, args.random).items()})
        print(f"state {len(rows)}/{args.states} ({time.perf_counter() - start:.0f} s): "
              + ", ".join(f"{k.split(',')[0]} {v.mean():+.3f}" for k, v in rows[-1].items()), flush=True)

    print(f"\n{args.states} states ({', '.join(args.levels)}, train split), {time.perf_counter() - start:.0f} s; "
          "Δχ of the targets after one push (− reveals), mean ± 95 % CI over states")
    print(f"{'candidates':36s} {'pushes':>6s} {'mean Δχ':>16s} {'P(<−0.05)':>9s} {'P(>+0.05)':>9s} {'best per state':>16s}")
    for name in rows[0]:
        per_state = np.array([r[name].mean() for r in rows])
        best = np.array([r[name].min() for r in rows])
        every = np.concatenate([r[name] for r in rows])
        m, h, _ = mean_ci95(torch.from_numpy(per_state))
        bm, bh, _ = mean_ci95(torch.from_numpy(best))
        print(f"{name:36s} {len(every):6d} {m:+.3f} ± {h:.3f}    {np.mean(every < -0.05):9.2f} "
              f"{np.mean(every > 0.05):9.2f} {bm:+.3f} ± {bh:.3f}")


if __name__ == "__main__":
    main()

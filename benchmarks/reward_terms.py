"""Reward terms under the random baseline: per level, the mean of every term per push step, the
stop rewards, and the fraction of initial scenes that are already simple.

    python benchmarks/reward_terms.py --dataset data/mqa [--episodes 20] [--types counting]
"""

from __future__ import annotations

import argparse

import torch

from mqa_rl import keys
from mqa_rl.modules.random_policy import RandomMQAPolicy
from mqa_rl.transforms.mqa_env import make_mqa_env

ALL_TERMS = {
    "terms": {"exploration": {}, "global_occlusion": {}, "local_occlusion": {"reduce": "max"}},
    "question_weights": {"global_occlusion": 0.5, "local_occlusion": 0.5},
}
COLUMNS = ("exploration", "global_occlusion", "local_occlusion", "simple_scene")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--dataset", default="data/mqa")
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--types", nargs="+", default=["counting"])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    print(f"random policy, {args.episodes} episodes per level, questions: {args.types}; terms per push step (mean)")
    print(f"{'level':<8}{'pushes':>7}" + "".join(f"{c:>18}" for c in COLUMNS) + f"{'reward':>9}{'stop r':>8}{'simple@0':>10}")
    for level in ("easy", "medium", "hard"):
        env = make_mqa_env(args.dataset, ALL_TERMS, split=None, difficulties=[level], question_types=args.types,
                           seed=args.seed)
        policy = RandomMQAPolicy(env.base_env.max_pushes, seed=args.seed)
        steps, stops, simple0 = [], [], []
        for _ in range(args.episodes):
            with torch.no_grad():
                r = env.rollout(env.base_env.max_pushes + 1, policy)
            nxt = r["next"]
            stop = nxt[keys.IS_STOP].squeeze(-1)
            steps.append(nxt[~stop].select(keys.REWARD, keys.REWARD_TERMS))
            stops.append(nxt[keys.REWARD][stop])
            tgt, chi = r[keys.TARGET_MASK][0], r[keys.OVERLAP][0]
            simple0.append(bool((~tgt | (chi <= 0.2)).all()))
        pushes = torch.cat(steps) if steps else None
        means = [pushes[(keys.REWARD_TERMS, c)].mean().item() for c in COLUMNS]
        stop_r = torch.cat(stops).mean().item() if any(len(s) for s in stops) else float("nan")
        print(f"{level:<8}{pushes.shape[0]:>7}" + "".join(f"{m:>18.3f}" for m in means)
              + f"{pushes[keys.REWARD].mean().item():>9.3f}{stop_r:>8.2f}{sum(simple0) / len(simple0):>10.2f}")


if __name__ == "__main__":
    main()

"""Does answering need manipulation? Occlusion of the COUNTING targets on the first image, after the
paper's random baseline and after the privileged (oracle) push policy, per level.

For every COUNTING question of the chosen split: the fraction of its target objects fully hidden
(A_s = 0), mostly hidden (χ > 0.8) and nearly free (χ ≤ 0.2), and whether a *perfect counter* that
counts the targets with at least 1 px / 20 px / 5 % of A_t visible gives the right answer; plus the
mean pushes. The random baseline's pushes do not depend on the question, so each scene gets
``--random-episodes`` episodes and its questions take them in turn (every question still sees one
independent random episode). The privileged policy runs one episode per question whose targets are
not all revealed at reset (it stops at once otherwise).

    python benchmarks/occlusion.py --dataset data/mqa                 # test split, ~10 min on 2 cores
    python benchmarks/occlusion.py --dataset data/mqa --policies first   # first image only (~20 s)
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict

import numpy as np
import torch

from mqa_rl import keys
from mqa_rl.data import MQADataset
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.modules.privileged_policy import PrivilegedPushPolicy
from mqa_rl.modules.random_policy import RandomMQAPolicy

LEVELS = ("easy", "medium", "hard")
COUNTER_RULES = {"≥1px": lambda vis, full: vis >= 1, "≥20px": lambda vis, full: vis >= 20,
                 "≥5%A_t": lambda vis, full: vis >= 0.05 * np.maximum(full, 1)}


def question_rows(question, classes: np.ndarray, m: dict, pushes: int) -> dict:
    """The statistics of one question on one (measured) image."""
    target = classes == question.classes[0]
    vis, full, chi = m["visible"][target], m["full"][target], m["overlap"][target]
    row = {"targets": int(target.sum()), "hidden": int((vis == 0).sum()), "chi>0.8": int((chi > 0.8).sum()),
           "chi<=0.2": int((chi <= 0.2).sum()), "pushes": pushes}
    for name, rule in COUNTER_RULES.items():
        row[name] = float(int(rule(vis, full).sum()) == int(question.answer))
    return row


def run_episode(env: SapienBinEnv, question, policy) -> tuple[dict, int]:
    """One episode from ``question``'s scene; the final measurement and the pushes used."""
    td = env.reset(question_id=question.id)
    pushes = 0
    while True:
        td = policy(td)
        if int(td[keys.ACTION]) == actions.STOP:
            break
        td = env.step(td)["next"]
        pushes += 1
        if td["truncated"].item():
            break
    return env.measure(), pushes


def collect(ds: MQADataset, split: str, policies: list[str], random_episodes: int, max_scenes: int | None, seed: int,
            lookahead: int, levels=LEVELS, min_visible_fraction: float = 0.0):
    env = SapienBinEnv(ds, split=split, question_types=["counting"], seed=seed)
    privileged = PrivilegedPushPolicy(env, lookahead=lookahead, min_visible_fraction=min_visible_fraction)
    rand = RandomMQAPolicy(max_pushes=env.max_pushes, seed=seed)
    rows = defaultdict(list)                    # (policy, level) -> list of question rows
    scenes = [s for s in ds.scenes if s.split == split and s.difficulty in levels][:max_scenes]
    for scene in scenes:
        qs = [q for q in ds.select(split=split, types=["counting"]) if q.scene_id == scene.id]
        classes = np.array([o.class_name for o in scene.objects])
        env.reset(question_id=qs[0].id)
        first = env.measure()
        if "first" in policies:
            rows["first", scene.difficulty] += [question_rows(q, classes, first, 0) for q in qs]
        if "random" in policies:
            episodes = [run_episode(env, qs[k], rand) for k in range(min(random_episodes, len(qs)))]
            rows["random", scene.difficulty] += [question_rows(q, classes, *episodes[i % len(episodes)]) for i, q in enumerate(qs)]
        if "privileged" in policies:
            for q in qs:
                target = classes == q.classes[0]
                if privileged.revealed(first["visible"][target], first["full"][target]).all():
                    rows["privileged", scene.difficulty].append(question_rows(q, classes, first, 0))
                else:
                    rows["privileged", scene.difficulty].append(question_rows(q, classes, *run_episode(env, q, privileged)))
    return rows


def summarise(rows: dict, policies: list[str]) -> str:
    cols = ["hidden", "chi>0.8", "chi<=0.2", *COUNTER_RULES, "pushes"]
    lines = [f"| policy | level | questions | targets | {' | '.join(cols)} |", "|" + "---|" * (len(cols) + 4)]
    for policy in policies:
        for level in LEVELS:
            r = rows.get((policy, level), [])
            if not r:
                continue
            n_t = max(sum(x["targets"] for x in r), 1)
            cells = [f"{sum(x[c] for x in r) / n_t:.3f}" for c in ("hidden", "chi>0.8", "chi<=0.2")]
            for c in COUNTER_RULES:
                acc = np.mean([x[c] for x in r])
                half = 1.96 * np.sqrt(acc * (1 - acc) / len(r))
                cells.append(f"{acc:.3f} ± {half:.3f}")
            cells.append(f"{np.mean([x['pushes'] for x in r]):.2f}")
            lines.append(f"| {policy} | {level} | {len(r)} | {n_t} | {' | '.join(cells)} |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default="data/mqa")
    p.add_argument("--split", default="test")
    p.add_argument("--policies", default="first,random,privileged")
    p.add_argument("--random-episodes", type=int, default=4, help="random episodes per scene")
    p.add_argument("--max-scenes", type=int, default=None)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--lookahead", type=int, default=1, help="pushes the privileged policy simulates per step")
    p.add_argument("--levels", default=",".join(LEVELS))
    p.add_argument("--min-visible-fraction", type=float, default=0.0,
                   help="the privileged policy stops when every target has ≥ 20 px and this fraction of A_t visible "
                        "(0: the ≥20px counter's own criterion; the policy's default 0.3 suits a VQA that must see more)")
    a = p.parse_args()
    torch.set_num_threads(1)
    policies = a.policies.split(",")
    t0 = time.perf_counter()
    rows = collect(MQADataset(a.dataset), a.split, policies, a.random_episodes, a.max_scenes, a.seed, a.lookahead,
                   a.levels.split(","), a.min_visible_fraction)
    print(f"COUNTING targets on the {a.split} split of {a.dataset} ({time.perf_counter() - t0:.0f} s); "
          "fractions of targets, perfect-counter accuracy ± 95 % CI, mean pushes")
    print(summarise(rows, policies))


if __name__ == "__main__":
    main()

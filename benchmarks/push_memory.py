"""What is a push memory worth to a policy? The same policy on the same questions under two ``push_memory``
settings (``PushMemory``: no push twice in an episode; -1: none), paired by question, 95 % intervals that
resample whole scenes: pushes that moved nothing (5 mm), pushes, χ at the end, targets fully hidden at the end,
net targets made countable, the perfect counter on I_stop.

    A="run=checkpoints/dqn_geometric_student stop_critic=checkpoints/stop_geometric_student policies=[greedy] episodes_per_level=150"
    python recipes/evaluate_policy.py $A out_dir=runs/memory/none                 # the run's own memory (none)
    python recipes/evaluate_policy.py $A push_memory=1 out_dir=runs/memory/twice   # no push twice (radius 1)
    python benchmarks/push_memory.py runs/memory/none runs/memory/twice
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import argparse
from pathlib import Path

import torch

from mqa_rl.evaluation.episode_metrics import scene_bootstrap_ci95
from mqa_rl.files import load_tensors

MEASURES = ("idle_pushes", "pushes", "chi_end", "hidden_end", "countable_gain", "counter_stop")


def load(folder: Path, level: str) -> tuple[dict, dict]:
    blob = load_tensors(folder / "episodes" / f"greedy_{level}.pt", what="evaluate_policy episodes file",
                        hint="run recipes/evaluate_policy.py with policies=[greedy] into that out_dir first")
    return blob["meta"], blob["metrics"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("first", type=Path, help="evaluate_policy out_dir under one push memory")
    p.add_argument("second", type=Path, help="evaluate_policy out_dir of the same run and questions under another")
    p.add_argument("--levels", nargs="+", default=["easy", "medium", "hard"])
    a = p.parse_args()
    one, two = a.first.name, a.second.name
    print(f"| level | measure | {one} | {two} | {two} − {one} (95 % by scene) |\n|---|---|---|---|---|")
    for level in a.levels:
        (meta_a, m_a), (meta_b, m_b) = load(a.first, level), load(a.second, level)
        differ = {k for k in set(meta_a) | set(meta_b) if k != "push_memory" and meta_a.get(k) != meta_b.get(k)}
        if differ or not torch.equal(m_a["scene"], m_b["scene"]):
            raise SystemExit(f"{level}: the two evaluations ran other questions or settings ({sorted(differ) or 'scenes'}): "
                             f"run both with the same run, dataset, split, seed and episodes_per_level")
        for k in MEASURES:
            diff = m_b[k] - m_a[k]
            ok = torch.isfinite(diff)
            mean, low, high, _ = scene_bootstrap_ci95(diff[ok], m_a["scene"][ok])
            print(f"| {level} | {k} | {m_a[k][ok].mean():.3f} | {m_b[k][ok].mean():.3f} | {mean:+.3f} [{low:+.3f}, {high:+.3f}] |")


if __name__ == "__main__":
    main()

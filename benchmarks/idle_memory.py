"""Is a memory of pushes that changed nothing worth it? The same policy on the same questions without and with
``idle_memory`` (``PushMemory``: after a push that changed almost nothing in the image, no push of any direction
near it for the rest of the episode), paired by question, 95 % intervals that resample whole scenes.

    python recipes/evaluate_policy.py run=checkpoints/dqn_geometric_student stop_critic=checkpoints/stop_geometric_student \
        'policies=[greedy]' episodes_per_level=150 out_dir=runs/idle/today
    python recipes/evaluate_policy.py run=checkpoints/dqn_geometric_student stop_critic=checkpoints/stop_geometric_student \
        'policies=[greedy]' episodes_per_level=150 idle_memory=1 out_dir=runs/idle/memory
    python benchmarks/idle_memory.py runs/idle/today runs/idle/memory
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
    p.add_argument("today", type=Path, help="evaluate_policy out_dir without idle_memory")
    p.add_argument("memory", type=Path, help="evaluate_policy out_dir of the same run and questions with idle_memory")
    p.add_argument("--levels", nargs="+", default=["easy", "medium", "hard"])
    a = p.parse_args()
    print("| level | measure | today | with idle memory | memory − today (95 % by scene) |\n|---|---|---|---|---|")
    for level in a.levels:
        (meta_a, m_a), (meta_b, m_b) = load(a.today, level), load(a.memory, level)
        differ = {k for k in set(meta_a) | set(meta_b) if k != "idle_memory" and meta_a.get(k) != meta_b.get(k)}
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

"""A kept-frame system against the others' last frames: from an ``evaluate_policy.py kept_frame=...`` run, greedy's
``counter_kept`` / ``countable_gain_kept`` / ``chi_kept`` / ``hidden_kept`` minus random's and no manipulation's
``counter_stop`` / ``countable_gain`` / ``chi_end`` / ``hidden_end``, paired by question, 95 % by scene (the system
answers from its kept frame, the baselines from their last). ``results.md``'s own ``greedy-random`` pairs kept with
kept (random given the same memory).

    python benchmarks/kept_frame_pairs.py runs/eval58/heldout
    python benchmarks/kept_frame_pairs.py runs/eval58/test runs/eval57/test   # baselines reused from an earlier run
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import argparse
from pathlib import Path

import torch

from mqa_rl.evaluation.episode_metrics import scene_bootstrap_ci95
from mqa_rl.files import load_tensors

PAIRS = (("counter_kept", "counter_stop"), ("countable_gain_kept", "countable_gain"), ("chi_kept", "chi_end"),
         ("hidden_kept", "hidden_end"))


def episodes(folder: Path, name: str, level: str) -> dict:
    return load_tensors(folder / "episodes" / f"{name}_{level}.pt", what="evaluate_policy.py episodes file",
                        hint="give the out_dir of an evaluate_policy.py run (kept_frame=... for greedy)")["metrics"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", help="the out_dir of evaluate_policy.py kept_frame=<perception.pt>")
    p.add_argument("baselines", nargs="?", default=None, help="where random's / no manipulation's episodes are "
                   "(the baseline_from= of that run; default: the run itself)")
    a = p.parse_args()
    run = Path(a.run)
    base = Path(a.baselines) if a.baselines else run
    for level in ("easy", "medium", "hard"):
        greedy = episodes(run, "greedy", level)
        if "counter_kept" not in greedy:
            raise SystemExit(f"{run}: greedy has no kept-frame measures: run evaluate_policy.py with kept_frame=")
        for other in ("random", "no_manipulation"):
            them = episodes(base, other, level)
            cells = []
            for kept, last in PAIRS:
                diff = greedy[kept] - them[last]
                ok = torch.isfinite(diff)
                mean, low, high, _ = scene_bootstrap_ci95(diff[ok], greedy["scene"][ok])
                cells.append(f"{kept} {mean:+.3f} [{low:+.3f}, {high:+.3f}]")
            print(f"{level:6} kept − {other} (last frame): " + " | ".join(cells))


if __name__ == "__main__":
    main()

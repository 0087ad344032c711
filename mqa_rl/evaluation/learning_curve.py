"""A DQN run's learning curve: its snapshots (the Q-network every so many frames) evaluated against random on the
same questions, drawn as greedy − random per level with 95 % intervals by scene, several runs on one plot."""

from __future__ import annotations

import json
import math
from pathlib import Path

from mqa_rl.data.dataset import LEVELS
from mqa_rl.evaluation.answering_report import save_figure

SNAPSHOTS = "snapshots"
# what the curve shows: the targets' mean hidden fraction at the end (lower is better) and the net targets made
# countable per episode (higher is better), each as greedy − the baseline on the same question
CURVE_METRICS = {"chi_end": "targets' χ at the end − random", "countable_gain": "targets made countable − random"}


def run_snapshots(run: str | Path) -> list[tuple[int, Path]]:
    """``[(frames, folder)]`` of a run's snapshots, oldest first."""
    folder = Path(run) / SNAPSHOTS
    found = []
    for path in folder.glob("checkpoint-*") if folder.is_dir() else ():
        suffix = path.name.removeprefix("checkpoint-")
        if suffix.isdigit() and (path / "manifest.json").is_file():
            found.append((int(suffix), path))
    return sorted(found)


def read_curve(path: str | Path) -> list[tuple[int, dict]]:
    """The points of a ``curve.json`` written by ``evaluate_policy.py snapshots=true``."""
    data = json.loads(Path(path).read_text())
    return [(int(p["frames"]), p["results"]) for p in data["points"]]


def curve_series(points: list[tuple[int, dict]], level: str, metric: str, base: str = "random"):
    """``(frames, mean, low, high)`` lists of greedy − ``base`` for one level and metric (intervals by scene)."""
    xs, mean, low, high = [], [], [], []
    for frames, results in points:
        diff = results.get(level, {}).get(f"greedy-{base}", {}).get(metric)
        if not diff or not math.isfinite(diff.get("mean", math.nan)):
            continue
        xs.append(frames)
        mean.append(diff["mean"])
        low.append(diff.get("scene_low", diff["mean"] - diff.get("ci95", 0.0)))
        high.append(diff.get("scene_high", diff["mean"] + diff.get("ci95", 0.0)))
    return xs, mean, low, high


def plot_learning_curves(curves: dict[str, list[tuple[int, dict]]], path: Path, base: str = "random") -> Path:
    """One column per level, one row per metric of ``CURVE_METRICS``; a line with its interval band per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(CURVE_METRICS), len(LEVELS), figsize=(4 * len(LEVELS), 3.2 * len(CURVE_METRICS)),
                             squeeze=False, sharex=True)
    for row, (metric, title) in enumerate(CURVE_METRICS.items()):
        for col, level in enumerate(LEVELS):
            ax = axes[row][col]
            for label, points in curves.items():
                xs, mean, low, high = curve_series(points, level, metric, base)
                if xs:
                    line, = ax.plot(xs, mean, marker="o", ms=3, label=label)
                    ax.fill_between(xs, low, high, color=line.get_color(), alpha=0.2)
            ax.axhline(0.0, color="k", lw=0.8)
            ax.set_title(f"{level}: {title.replace('random', base)}", fontsize=9)
            ax.grid(alpha=0.3)
            if row == len(CURVE_METRICS) - 1:
                ax.set_xlabel("frames")
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, Path(path), dpi=110)

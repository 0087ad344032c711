"""The paper's Fig. 7 from train_dqn.py logs: reward per episode in training and testing, one panel
per run (variant), saved as PNG.

    python recipes/plot_curves.py outputs/train_dqn/global/<t> outputs/train_dqn/local/<t> \
        outputs/train_dqn/global_local/<t> --out fig7.png

Training reward: the mean over the episodes that ended in each logged batch (``train/reward``),
smoothed with a moving average over ``--window`` points; testing: the greedy evaluations
(``eval/reward``). The x axis is collected frames (env steps).

The learning curves of runs evaluated at every snapshot (greedy − random per level, 95 % by scene), on one plot:

    python recipes/plot_curves.py --learning runs/curves/global runs/curves/local runs/curves/global_local --out curves.png

Runs trained from demonstrations also get ``<out>_pretraining.png``: the pre-training's demonstration
loss and how often the greedy push lands near the demonstrated one (``demo_near``) and the stop-or-push
decision agrees (``demo_stop_agreement``), per update. A run of pre-training alone gets only that figure.
"""

from __future__ import annotations

import argparse
import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mqa_rl.evaluation.answering_report import save_figure  # noqa: E402
from mqa_rl.evaluation.learning_curve import plot_learning_curves, read_curve  # noqa: E402


def read_scalar(run: Path, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(steps, values) of one logged scalar, e.g. ``train/reward``; empty arrays if never logged."""
    path = run / "csv" / "scalars" / f"{name}.csv"
    if not path.exists():
        return np.zeros(0), np.zeros(0)
    rows = np.loadtxt(path, delimiter=",", ndmin=2)
    return rows[:, 0], rows[:, 1]


def smooth(values: np.ndarray, window: int) -> np.ndarray:
    if window <= 1 or len(values) < window:
        return values
    kernel = np.ones(window) / window
    return np.convolve(np.pad(values, (window - 1, 0), mode="edge"), kernel, mode="valid")


def label(run: Path) -> str:
    cfg = run / "config.yaml"
    if cfg.exists():
        from omegaconf import OmegaConf

        c = OmegaConf.load(cfg)
        extras = [name for name, on in (("recognition", c.model.get("class_map")), ("demonstrations", (c.get("demos") or {}).get("path")),
                                        ("no mask", not c.get("action_mask", True))) if on]
        return f"DQN ({c.reward.name}, {c.model.trunk}{''.join(', ' + e for e in extras)}): {run.name}"
    return run.name


def plot_pretraining(runs: list[Path], out: Path) -> Path:
    """One panel per run: demonstration loss (left axis) and agreement with the demonstrator (right)."""
    fig, axes = plt.subplots(1, len(runs), figsize=(5 * len(runs), 3.6), squeeze=False)
    for ax, run in zip(axes[0], runs):
        steps, loss = read_scalar(run, "demo_pretrain/loss_demo")
        ax.plot(steps, loss, color="tab:blue", label="demonstration loss")
        ax.set_xlabel("pre-training updates")
        ax.set_ylabel("loss")
        right = ax.twinx()
        for name, color in (("demo_near", "tab:orange"), ("demo_stop_agreement", "tab:green")):
            s, v = read_scalar(run, f"demo_pretrain/{name}")
            right.plot(s, v, color=color, label=name.replace("_", " "))
        right.set_ylim(0, 1)
        right.set_ylabel("fraction of demonstrations")
        ax.set_title(textwrap.fill(label(run), 48), fontsize=9)
        ax.grid(alpha=0.3)
        lines = ax.get_legend_handles_labels()[0] + right.get_legend_handles_labels()[0]
        ax.legend(lines, [line.get_label() for line in lines], fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3)
    fig.tight_layout()
    return save_figure(fig, out)


def plot(runs: list[Path], out: Path, window: int = 10) -> Path:
    fig, axes = plt.subplots(1, len(runs), figsize=(5 * len(runs), 3.6), squeeze=False)
    for ax, run in zip(axes[0], runs):
        steps, reward = read_scalar(run, "train/reward")
        if len(steps) == 0:
            raise FileNotFoundError(f"{run} has no csv/scalars/train/reward.csv (no training episode ended): is it a "
                                    f"train_dqn.py output folder?")
        ax.plot(steps, reward, color="tab:blue", alpha=0.25, lw=0.8)
        ax.plot(steps, smooth(reward, window), color="tab:blue", label="training")
        es, ev = read_scalar(run, "eval/reward")
        if len(es):
            ax.plot(es, ev, "o-", color="tab:orange", label="testing (greedy)")
        ax.set_title(textwrap.fill(label(run), 48), fontsize=9)   # long option lists wrap, not overlap
        ax.set_xlabel("env steps")
        ax.set_ylabel("reward per episode")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    return save_figure(fig, out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path, help="train_dqn.py output folders, one panel each; with --learning: "
                    "evaluate_policy.py snapshots=true output folders (their curve.json), one line each")
    ap.add_argument("--learning", action="store_true", help="the learning curves of several runs on one plot per level")
    ap.add_argument("--out", type=Path, default=Path("fig7_rewards.png"))
    ap.add_argument("--window", type=int, default=10, help="moving-average window of the training curve")
    args = ap.parse_args()
    if args.learning:
        missing = [str(r) for r in args.runs if not (r / "curve.json").is_file()]
        if missing:
            raise SystemExit(f"no curve.json in {', '.join(missing)}: make it with "
                             f"`python recipes/evaluate_policy.py run=<run> snapshots=true out_dir=<folder>`")
        print(plot_learning_curves({r.name: read_curve(r / "curve.json") for r in args.runs}, args.out))
        return
    pretrained = [run for run in args.runs if len(read_scalar(run, "demo_pretrain/loss_demo")[0])]
    if pretrained:
        print(plot_pretraining(pretrained, args.out.with_name(f"{args.out.stem}_pretraining{args.out.suffix}")))
    rl = [run for run in args.runs if run not in pretrained or len(read_scalar(run, "train/reward")[0])]
    if rl:                  # every run without pre-training is here: plot() names one that is no train_dqn.py run
        print(plot(rl, args.out, args.window))


if __name__ == "__main__":
    main()

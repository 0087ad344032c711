"""The paper's Fig. 7 from a ``train_dqn.py`` run's logs: reward per episode in training and testing, one panel per
run, and for a run trained from demonstrations its pre-training curves. Read from the runs' CSV scalars, so that
any run folder draws the same figure whatever dashboards it logged to."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from mqa_rl.evaluation.answering_report import save_figure


def _pyplot():
    """matplotlib's pyplot on the file-only Agg backend, imported when a figure is drawn (it is slow to load)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


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
    plt = _pyplot()
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


def plot_reward_curves(runs: list[Path], out: Path, window: int = 10) -> Path:
    """One panel per run: training reward per episode (raw and smoothed over ``window`` points) and the greedy
    evaluations' reward, against collected frames."""
    plt = _pyplot()
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

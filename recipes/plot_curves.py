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
from pathlib import Path

from mqa_rl.evaluation.learning_curve import plot_learning_curves, read_curve
from mqa_rl.evaluation.reward_curves import plot_pretraining, plot_reward_curves, read_scalar


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
    if rl:                  # every run without pre-training is here: plot_reward_curves() names one that is no train_dqn.py run
        print(plot_reward_curves(rl, args.out, args.window))


if __name__ == "__main__":
    main()

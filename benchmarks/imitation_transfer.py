"""Does a student's imitation carry over to new scenes? Its agreement with the teacher on the demonstrations
it trained on against demonstrations from scenes it never saw.

For each trained run (``train_dqn.py`` output or export) and each demonstration folder
(``recipes/collect_demonstrations.py``; e.g. the training folder and one collected with ``env.split=test``
by the same teacher), prints over the demonstrated pushes how often the greedy push (inside the action mask)
is the teacher's, is near it (same direction, start within 3 cells), and how often its best direction at the
teacher's start cell is the teacher's (chance 1/8); over all states, how often push-or-stop agrees. A gap
between the two folders is memorisation; no gap and low agreement is under-fitting.

    python recipes/collect_demonstrations.py states=300 env.split=test oracle.order=visible_first \
        oracle.geometry=visible oracle.refine_radius=1 out_dir=runs/demos_refined_test
    python benchmarks/imitation_transfer.py --runs runs/refined_student checkpoints/dqn_refined_student \
        --demos runs/demos_refined runs/demos_refined_test
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).parents[1]))
sys.path.insert(0, str(Path(__file__).parent))

from imitation_probe import scores  # noqa: E402

from mqa_rl import keys  # noqa: E402
from mqa_rl.collectors.demonstrations import load_demonstrations  # noqa: E402
from mqa_rl.envs import actions  # noqa: E402
from mqa_rl.envs.sapien_bin import SapienBinEnv  # noqa: E402
from mqa_rl.modules.push_qnet import PushQNet  # noqa: E402
from mqa_rl.modules.trained_policy import load_greedy  # noqa: E402

ROOT = Path(__file__).parents[1]


@torch.no_grad()
def stop_agreement(net: PushQNet, demos, batch: int = 64) -> float:
    """Fraction of states where the masked greedy action is stop exactly when the teacher's is."""
    agree = 0
    for i in range(0, len(demos), batch):
        td = demos[i:i + batch]
        q = net(td[keys.RGB], td[keys.DEPTH], td[keys.QUESTION]).masked_fill(~td[keys.ACTION_MASK], torch.finfo(torch.float32).min)
        agree += int(((q.argmax(-1) == actions.STOP) == (td[keys.ACTION] == actions.STOP)).sum())
    return agree / len(demos)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", nargs="+", type=Path, required=True, help="train_dqn.py output folders or exports")
    ap.add_argument("--demos", nargs="+", type=Path, required=True, help="collect_demonstrations.py folders")
    ap.add_argument("--dataset", type=Path, default=ROOT / "data" / "mqa")
    ap.add_argument("--max-states", type=int, default=500, help="the first this many states of each folder")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    env = SapienBinEnv(str(args.dataset), split="test")
    folders = {}
    for path in args.demos:
        demos = load_demonstrations(path, args.dataset)[: args.max_states]
        allowed = demos[keys.ACTION_MASK].gather(-1, demos[keys.ACTION][:, None]).squeeze(-1)
        folders[path] = demos[allowed]              # the teacher's pushes the mask forbids: no greedy push can match
    print("run | demonstrations | states | pushes | greedy = teacher's | near it | direction at its cell | push-or-stop agrees")
    for run in args.runs:
        actor, _, _ = load_greedy(run, None, env)
        net = next(m for m in actor.modules() if isinstance(m, PushQNet)).eval()
        for path, demos in folders.items():
            same, near, _, direction = scores(net, demos)
            pushes = int((demos[keys.ACTION] != actions.STOP).sum())
            print(f"{run} | {path} | {len(demos)} | {pushes} | {same:.3f} | {near:.3f} | {direction:.3f} | "
                  f"{stop_agreement(net, demos):.3f}", flush=True)
    env.close()


if __name__ == "__main__":
    main()

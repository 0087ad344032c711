"""What the counting perception reads of the asked class on the frames a system answers from: on each COUNTING
episode of a rollout store, its count (rounded and expected) on I_stop (or I_start) against the visible count (targets
with ≥ 20 px, the perfect counter's rule) and against the answer, per level. Beside a store of the same episodes with
another frame kept, it shows whether a frame choice biases what the perception reads (docs/policy.md, "the winner's
curse": a keeper that picks the highest reading also picks over-counts).

    python benchmarks/perceived_on_rollouts.py \\
        --rollouts runs/answering448/rollouts/counting/dqn_countable_perceived/test \\
                   runs/answering448/rollouts/counting/dqn_countable_kept/test
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import argparse

import torch

from mqa_rl import keys
from mqa_rl.collectors.store import load_records
from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import LEVELS
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.evaluation.answering import countable_targets
from mqa_rl.modules.perceived_count import READING, PerceivedCount, token_channels
from mqa_rl.training.vqa_data import frame_keys


@torch.no_grad()
def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rollouts", nargs="+", required=True, help="rollout stores of collect_rollouts.py (test splits)")
    p.add_argument("--perception", default="checkpoints/vqa_counting/perception.pt")
    p.add_argument("--dataset", default="data/mqa", help="the dataset the stores were collected on (its classes)")
    p.add_argument("--frame", choices=("first", "last"), default="last", help="I_start or I_stop")
    a = p.parse_args()
    reading = PerceivedCount.from_file(a.perception, token_channels(MQADataset(a.dataset)))
    frame = keys.FIRST if a.frame == "first" else keys.LAST
    print(f"{'store':60} {'level':6} {'n':>4} {'exp-vis':>8} {'too many':>9} {'too few':>8} {'cnt=vis':>8} "
          f"{'cnt=ans':>8} {'vis=ans':>8}")
    for store in a.rollouts:
        image = frame_keys(store, reading.input_size)[0 if frame == keys.FIRST else 1]
        rec = load_records(store, (keys.QUESTION, keys.LEVEL, keys.TYPE_LABEL, keys.EPISODE_TARGETS,
                                   (keys.FIRST, keys.FRAME_VISIBLE), (keys.LAST, keys.FRAME_VISIBLE), image))
        rec = rec[rec.get(keys.TYPE_LABEL) == QUESTION_TYPES.index("counting")]
        out = torch.cat([reading(rec.get(image)[i:i + 32], rec.get(keys.QUESTION)[i:i + 32])
                         for i in range(0, len(rec), 32)])
        count, expected = out[:, READING.index("perceived_count")], out[:, READING.index("perceived_expected")]
        visible, answer = countable_targets(rec, frame).float(), rec.get(keys.EPISODE_TARGETS).sum(-1).float()
        for i, level in enumerate(LEVELS):
            m = rec.get(keys.LEVEL) == i
            if not m.any():
                continue
            mean = lambda x: float(x[m].float().mean())          # noqa: E731
            print(f"{store[-60:]:60} {level:6} {int(m.sum()):>4} {mean(expected - visible):>+8.3f} "
                  f"{mean(count > visible):>9.3f} {mean(count < visible):>8.3f} {mean(count == visible):>8.3f} "
                  f"{mean(count == answer):>8.3f} {mean(visible == answer):>8.3f}")


if __name__ == "__main__":
    main()

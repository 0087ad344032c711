"""How well does a pretrained VQA encoder count the asked class on scenes it never saw? Its density head's
sum for the question's class, rounded (0-3), against the targets with >= 20 visible pixels (what
evaluate.py's perfect counter reads) and against the answer, per level, on a system's test rollouts. It judges
an encoder in seconds, before any VQA is trained on it (docs/results.md, "Which class is the question about?").

    python benchmarks/encoder_counts.py --encoder checkpoints/vqa_encoder/encoder.pt \
        --rollouts runs/answering/rollouts/counting/no_manipulation/test
    python benchmarks/encoder_counts.py --encoder ... --rollouts .../dqn_student/test --frame last   # after the pushes
"""

from __future__ import annotations

import argparse

import torch

from mqa_rl import keys
from mqa_rl.collectors.store import load_records
from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import LEVELS
from mqa_rl.evaluation.answering import countable_targets
from mqa_rl.modules.vqa_encoder import load_encoder, standardise


@torch.no_grad()
def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--encoder", required=True)
    p.add_argument("--rollouts", required=True, help="a rollout store (e.g. .../no_manipulation/test)")
    p.add_argument("--frame", choices=("first", "last"), default="first", help="I_start or I_stop")
    p.add_argument("--dataset", default="data/mqa")
    a = p.parse_args()
    ds = MQADataset(a.dataset)
    encoder, _ = load_encoder(a.encoder)
    encoder.eval()
    frame, rgb = (keys.FIRST, keys.FIRST_RGB) if a.frame == "first" else (keys.LAST, keys.LAST_RGB)
    rec = load_records(a.rollouts, (keys.QUESTION_ID, keys.ANSWER_LABEL, keys.LEVEL, rgb,
                                    (frame, keys.FRAME_VISIBLE), keys.EPISODE_TARGETS))
    visible = countable_targets(rec, frame)                                                 # what a perfect counter reads
    rows = {lv: [] for lv in range(len(LEVELS))}
    for start in range(0, rec.shape[0], 64):
        batch = rec[start:start + 64]
        maps = encoder.class_maps(standardise(batch[rgb], encoder.image_size))
        density = maps[:, maps.shape[1] // 2:].sum((-1, -2))                                  # [B, K] objects per class
        for j in range(batch.shape[0]):
            q = ds.questions[int(batch[keys.QUESTION_ID][j])]
            if q.type != "counting":
                continue
            estimate = int(min(3, max(0, round(float(density[j, 1 + ds.classes.index(q.classes[0])])))))
            rows[int(batch[keys.LEVEL][j])].append((estimate, int(visible[start + j]), int(q.answer)))
    print(f"{a.encoder} on {a.rollouts} ({a.frame} images, COUNTING questions):")
    for lv, r in rows.items():
        if r:
            t = torch.tensor(r, dtype=torch.float64)
            print(f"  {LEVELS[lv]:6s} n={len(r):4d}  density count = visible {float((t[:, 0] == t[:, 1]).double().mean()):.3f}  "
                  f"= answer {float((t[:, 0] == t[:, 2]).double().mean()):.3f}  (perfect counter = answer {float((t[:, 1] == t[:, 2]).double().mean()):.3f}; "
                  f"mean |count - visible| {float((t[:, 0] - t[:, 1]).abs().mean()):.2f})")


if __name__ == "__main__":
    main()

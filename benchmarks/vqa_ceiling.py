"""How well could the VQA answer with perfect perception? The paper's answering head (question LSTM,
attention over I_start and I_stop, fusion, softmax) with ``vqa=counting``'s count pool fed the TRUE count
features of both frames (every object's visible pixels from the stored rollouts, in the perception's own
feature layout: ``vote_counting.features_from_masses``), trained *with the grounding loss* as
recipes/train_vqa.py trains it, on a system's training rollouts; COUNTING accuracy on its test rollouts
per level. What the head allows, separated from what the perception learns: a trained perception's VQA
should come close to this, and this close to the calibrated either-frame counter of evaluate.py.

    python recipes/collect_rollouts.py system=no_manipulation
    python benchmarks/vqa_ceiling.py --rollouts runs/answering/rollouts/counting/no_manipulation
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import argparse
import time
from pathlib import Path

import torch

from mqa_rl import keys
from mqa_rl.collectors.store import load_records
from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import LEVELS
from mqa_rl.losses.vqa import VQALoss
from mqa_rl.modules import vote_counting
from mqa_rl.modules.vqa import VQAModel, grounding_module, vqa_module
from mqa_rl.training.vqa_data import RECORD_KEYS, Batches, question_class_labels

TINY_PERCEPTION = {"widths": [8, 8, 8, 8], "image_size": 112}     # unused: the features are given


def true_features(store: Path, ds: MQADataset):
    """Records with FIRST / LAST_FEATURES [N, 1, K, F]: the count features of a perfect perception."""
    k = 1 + len(ds.classes)
    records = load_records(store, (*RECORD_KEYS, (keys.FIRST, keys.FRAME_VISIBLE), (keys.LAST, keys.FRAME_VISIBLE)))
    scene_classes, features = {}, {}
    for frame, out in ((keys.FIRST, keys.FIRST_FEATURES), (keys.LAST, keys.LAST_FEATURES)):
        visible = records.get((frame, keys.FRAME_VISIBLE))
        masses, areas = [], torch.zeros(records.shape[0], k - 1)
        for i, scene in enumerate(records.get(keys.SCENE).tolist()):
            if scene not in scene_classes:
                scene_classes[scene] = torch.tensor([1 + ds.classes.index(o.class_name) for o in ds.scenes[scene].objects])
            classes = scene_classes[scene]
            v = visible[i, :len(classes)]
            masses.append([v[(classes == c) & (v > 0)] for c in range(1, k)])
            areas[i] = torch.zeros(k - 1).index_add_(0, classes - 1, v)
        features[out] = vote_counting.features_from_masses(masses, areas).unsqueeze(1).to(torch.float16)
    records = records.exclude(keys.FIRST, keys.LAST)
    records.update(features)
    records.set(keys.QUESTION_CLASSES, question_class_labels(records, ds))
    return records


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default="data/mqa")
    p.add_argument("--rollouts", type=Path, required=True, help="a system's rollouts folder (holding train/ and test/)")
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(a.seed)
    ds = MQADataset(a.dataset)
    t0 = time.process_time()
    train, test = true_features(a.rollouts / "train", ds), true_features(a.rollouts / "test", ds)
    model = VQAModel(ds.vocab.itos, ds.answers, pool="counts", dropout=0.3, cell_heads=2,
                     perception={"num_classes": 1 + len(ds.classes), **TINY_PERCEPTION})
    loss = VQALoss(vqa_module(model, from_features=True), grounding=grounding_module(model))
    optim = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=1e-3, weight_decay=1e-4)
    batches = Batches(train, 64, augment=False)
    for _ in range(a.steps):
        out = loss(batches.sample())
        optim.zero_grad()
        (out["loss_vqa"] + out["loss_grounding"]).backward()
        optim.step()
    model.eval()
    with torch.no_grad():
        logits = loss.network(Batches(test, 64, augment=False).take(torch.arange(len(test)))).get(keys.ANSWER_LOGITS)
    right = logits.argmax(-1) == test[keys.ANSWER_LABEL]
    levels = test[keys.LEVEL]
    acc = {lv: round(right[levels == i].float().mean().item(), 3) for i, lv in enumerate(LEVELS) if (levels == i).any()}
    print(f"the counting head on true count features of {a.rollouts.name}: COUNTING test accuracy {acc} "
          f"({time.process_time() - t0:.0f} CPU-s, {a.steps} steps, seed {a.seed})")


if __name__ == "__main__":
    main()

"""How well could the VQA count with perfect perception? The ``classes`` pool fed the TRUE class areas
of every cell (from the stored object maps) at a chosen grid size instead of the encoder's predictions,
trained on a system's training rollouts and tested on its test rollouts (COUNTING accuracy per level).
It separates what the answering head and the map's resolution allow from what the encoder learns.

    python recipes/collect_rollouts.py system=no_manipulation root=/tmp/exp
    python benchmarks/vqa_ceiling.py --rollouts /tmp/exp/rollouts/counting/no_manipulation --grid 10
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch
import torch.nn.functional as F

from mqa_rl import keys
from mqa_rl.collectors.store import load_records
from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import LEVELS
from mqa_rl.losses.vqa import VQALoss
from mqa_rl.modules.vqa import VQAModel, vqa_module
from mqa_rl.training.vqa_data import Batches, RECORD_KEYS


def true_maps(store: Path, ds: MQADataset, grid: int) -> "TensorDict":  # noqa: F821
    """Records with FIRST / LAST_FEATURES = [log class areas per cell, zero densities] at ``grid`` × ``grid``."""
    k = 1 + len(ds.classes)
    records = load_records(store, (*RECORD_KEYS, (keys.FIRST, keys.OBJECT_MAP), (keys.LAST, keys.OBJECT_MAP)))
    features = {}
    for frame, out in ((keys.FIRST, keys.FIRST_FEATURES), (keys.LAST, keys.LAST_FEATURES)):
        maps = []
        for i in range(records.shape[0]):
            objects = ds.scenes[int(records[keys.SCENE][i])].objects
            lut = torch.zeros(256, dtype=torch.long)
            lut[1:len(objects) + 1] = torch.tensor([1 + ds.classes.index(o.class_name) for o in objects])
            classes = lut[records[(frame, keys.OBJECT_MAP)][i].long()]
            area = F.adaptive_avg_pool2d(F.one_hot(classes, k).permute(2, 0, 1).float()[None], grid)[0]
            maps.append(torch.cat([torch.log(area + 1e-6), torch.zeros_like(area)]))
        features[out] = torch.stack(maps).unsqueeze(1).to(torch.float16)            # one "transform"
    records = records.exclude(keys.FIRST, keys.LAST)
    for key, value in features.items():
        records.set(key, value)
    return records


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default="data/mqa")
    p.add_argument("--rollouts", type=Path, required=True, help="a system's rollouts folder (holding train/ and test/)")
    p.add_argument("--grid", type=int, default=10)
    p.add_argument("--steps", type=int, default=3000)
    a = p.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    ds = MQADataset(a.dataset)
    t0 = time.process_time()
    train, test = true_maps(a.rollouts / "train", ds, a.grid), true_maps(a.rollouts / "test", ds, a.grid)
    model = VQAModel(ds.vocab.itos, ds.answers, pool="classes", dropout=0.3, encoder_classes=1 + len(ds.classes))
    loss = VQALoss(vqa_module(model, from_features=True))
    optim = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=1e-3)
    batches = Batches(train, 64, augment=False)
    for _ in range(a.steps):
        out = loss(batches.sample())
        optim.zero_grad()
        out["loss_vqa"].backward()
        optim.step()
    model.eval()
    with torch.no_grad():
        logits = loss.network(Batches(test, 64, augment=False).take(torch.arange(len(test)))).get(keys.ANSWER_LOGITS)
    right = logits.argmax(-1) == test[keys.ANSWER_LABEL]
    levels = test[keys.LEVEL]
    acc = {lv: round(right[levels == i].float().mean().item(), 3) for i, lv in enumerate(LEVELS) if (levels == i).any()}
    print(f"true class areas on a {a.grid}x{a.grid} grid: COUNTING test accuracy {acc} "
          f"({time.process_time() - t0:.0f} CPU-s)")


if __name__ == "__main__":
    main()

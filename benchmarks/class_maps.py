"""Where does a push policy think each class is? The class probabilities its Q-network reads on the 28 × 28 push grid
(its recognition's class head), or a counting perception's class map pooled to the same grid, against the simulator's
class fractions per cell (``SapienBinEnv.class_cells``), on a split's piles at rest and after random pushes:

    python benchmarks/class_maps.py --runs checkpoints/dqn_countable --dataset data/mqa_heldout     # fresh piles
    python benchmarks/class_maps.py --runs checkpoints/dqn_countable checkpoints/vqa_counting/perception.pt --split train

Per level, 95 % by scene: object cells (no-object fraction < 0.5) given their largest class, the mean IoU of each
present class's region (fraction ≥ 0.3, truth and prediction alike), and the L1 error of the class fractions.
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import argparse
import json
import time
from pathlib import Path

import torch
import torch.nn.functional as F

from mqa_rl import keys
from mqa_rl.collectors.perception_frames import scene_questions
from mqa_rl.data import MQADataset
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.evaluation.episode_metrics import scene_bootstrap_ci95
from mqa_rl.files import write_atomic
from mqa_rl.modules.perception import load_perception
from mqa_rl.modules.push_qnet import PushQNet
from mqa_rl.modules.trained_policy import load_greedy

REGION = 0.3            # a class's region: the cells it fills at least this much of
MEASURES = ("object_cells_right", "region_iou", "fraction_l1")


def class_map_reader(run: str, env):
    """rgb uint8 [3, H, W] → the class probabilities [1 + classes, 28, 28] the run's Q-network reads, or (a file) the
    counting perception's, its per-pixel probabilities averaged over each push-grid cell."""
    if Path(run).is_file():
        perception = load_perception(run)[0].eval()
        return lambda rgb: F.adaptive_avg_pool2d(perception.predict(rgb[None])[0].float(), actions.GRID)[0]
    actor, _, _ = load_greedy(run, None, env)
    net = next(m for m in actor.modules() if isinstance(m, PushQNet))
    if net.class_head is None:
        raise ValueError(f"{run}: its Q-network reads no class map (model.class_map=false)")
    return lambda rgb: torch.softmax(net.class_logits(rgb[None]), 1)[0]


def scores(pred: torch.Tensor, truth: torch.Tensor) -> tuple[float, float, float]:
    """``MEASURES`` of one state's predicted class probabilities against its true class fractions."""
    objects = truth[0] < 0.5
    right = (pred.argmax(0) == truth.argmax(0))[objects].float().mean()
    ious = [float(((t := truth[c] >= REGION) & (q := pred[c] >= REGION)).sum()) / float((t | q).sum())
            for c in range(1, truth.shape[0]) if (truth[c] >= REGION).any()]
    l1 = (pred[1:] - truth[1:]).abs().sum(0)[objects].mean()
    return float(right), sum(ious) / max(len(ious), 1), float(l1)


@torch.no_grad()
def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", nargs="+", required=True, help="train_dqn.py run folders (shipped ones included), or counting perception files")
    p.add_argument("--dataset", default="data/mqa")
    p.add_argument("--split", default="test")
    p.add_argument("--pushes", type=int, default=2, help="random pushes after the rest pile, each state scored")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", default=None, help="also write the figures to this file")
    a = p.parse_args()
    if a.pushes < 0:
        p.error(f"--pushes must be ≥ 0, got {a.pushes}")
    torch.set_num_threads(2)
    ds = MQADataset(a.dataset)
    env = SapienBinEnv(ds, split=None, max_pushes=max(1, a.pushes))
    readers = {run: class_map_reader(run, env) for run in a.runs}
    first, g, rows, t0 = scene_questions(ds), torch.Generator().manual_seed(a.seed), [], time.perf_counter()
    for i, scene in enumerate(ds.scenes):
        if scene.split != a.split:
            continue
        td = env.reset(question_id=first[scene.id])
        for k in range(a.pushes + 1):
            truth = torch.from_numpy(env.class_cells())
            rows.append((scene.difficulty, i, {run: scores(read(td[keys.RGB]), truth) for run, read in readers.items()}))
            if k < a.pushes:
                td = env.step(td.set(keys.ACTION, actions.random_push(td[keys.ACTION_MASK], g)))["next"]
    env.close()
    if not rows:
        p.error(f"{a.dataset} has no {a.split} scenes")
    report = {"dataset": a.dataset, "split": a.split, "pushes": a.pushes, "seconds": round(time.perf_counter() - t0, 1),
              "levels": {}}
    print(f"{a.dataset} {a.split}: {len(rows)} states ({a.pushes} random pushes after each rest pile), "
          f"{report['seconds']} s")
    for level in dict.fromkeys(r[0] for r in rows):
        mine = [r for r in rows if r[0] == level]
        scenes = torch.tensor([r[1] for r in mine])
        report["levels"][level] = {}
        for run in a.runs:
            values = torch.tensor([r[2][run] for r in mine])
            figures = {m: scene_bootstrap_ci95(values[:, j], scenes)[:3] for j, m in enumerate(MEASURES)}
            report["levels"][level][run] = figures
            print(f"  {level:6s} {run}: " + ", ".join(f"{m} {v[0]:.3f} [{v[1]:.3f}, {v[2]:.3f}]" for m, v in figures.items()))
    if a.json:
        write_atomic(Path(a.json), json.dumps(report, indent=1))


if __name__ == "__main__":
    main()

"""Does the counting perception count the asked class? On every COUNTING question of a split, its count
of the question's class on the scene's first image (rendered here) against the targets with ≥ 20
visible pixels (the perfect counter's rule) and against the answer, per level, with 95 % intervals
that resample whole scenes, and how often it counts too many or too few; and by the smallest countable
target's visible area.

    python benchmarks/perception_counts.py --perception checkpoints/vqa_counting/perception.pt
    python benchmarks/perception_counts.py --perception ... --dataset data/mqa_heldout     # fresh piles
    python benchmarks/perception_counts.py --perception A.pt --baseline B.pt               # A − B, paired by question

Each perception reads the same rest piles rendered at its own input size (the shipped file: 448 px; ``--render``
sets perception A's); the truth is always the 224-px render's (the answering episodes' and the perfect counter's).
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import argparse
import json
import time
from pathlib import Path

import torch

from mqa_rl import keys
from mqa_rl.collectors.perception_frames import scene_questions
from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import LEVELS
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.evaluation.episode_metrics import scene_bootstrap_ci95
from mqa_rl.files import write_atomic
from mqa_rl.modules.perception import RENDER_SIZE, load_perception
from mqa_rl.transforms.episode_stats import COUNTABLE_PX

AREA_BINS = ((20, 100), (100, 500), (500, float("inf")))


def first_images(ds: MQADataset, split: str, render: int = RENDER_SIZE):
    """{scene index: (rgb uint8 [3, H, W], visible px [n], class per object [n], depth [1, H, W])} of the split's
    rest piles, rendered at ``render`` px a side."""
    env = SapienBinEnv(ds, split=None, image_size=render)
    first = scene_questions(ds)
    out = {}
    for i, scene in enumerate(ds.scenes):
        if scene.split != split:
            continue
        td = env.reset(question_id=first[scene.id])
        n = len(scene.objects)
        out[i] = (td[keys.RGB], td[keys.VISIBLE_AREA][:n].clone(),
                  torch.tensor([1 + ds.classes.index(o.class_name) for o in scene.objects]), td[keys.DEPTH])
    env.close()
    return out


def count_scenes(model, scenes: dict, order: list[int]) -> dict:
    """{scene index: int64 [K-1]} the perception's count of each class on the scene's first image (with its
    depth image where the perception reads depth)."""
    counted = {}
    for start in range(0, len(order), 32):
        ids = order[start:start + 32]
        depth = torch.stack([scenes[i][3] for i in ids]) if model.depth else None
        for i, row in zip(ids, model.counts(torch.stack([scenes[i][0] for i in ids]), depth)):
            counted[i] = row
    return counted


@torch.no_grad()
def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--perception", required=True)
    p.add_argument("--dataset", default="data/mqa")
    p.add_argument("--split", default="test")
    p.add_argument("--baseline", default=None, help="another perception file: also A − baseline on the same images, "
                                                    "paired by question, 95 %% by scene")
    p.add_argument("--render", type=int, default=None, help="the side of the render perception A reads (default: its "
                                                      "input size; the same piles; the truth stays the 224-px one)")
    p.add_argument("--json", default=None, help="also write the figures to this file")
    a = p.parse_args()
    torch.set_num_threads(2)
    ds = MQADataset(a.dataset)
    model, meta = load_perception(a.perception)
    base = load_perception(a.baseline)[0] if a.baseline else None
    a.render = a.render or model.input_size
    for size in {a.render, base.input_size if base else RENDER_SIZE}:
        if size < RENDER_SIZE or size % RENDER_SIZE:
            p.error(f"a render must be a multiple of {RENDER_SIZE} px, got {size}")
    t0 = time.perf_counter()
    renders = {RENDER_SIZE: first_images(ds, a.split)}

    def rendered(size: int) -> dict:
        if size not in renders:
            renders[size] = first_images(ds, a.split, size)
        return renders[size]
    scenes, fine = renders[RENDER_SIZE], rendered(a.render)
    if base is not None:
        rendered(base.input_size)
    render_s = time.perf_counter() - t0
    order = sorted(scenes)
    t0 = time.perf_counter()
    counted = count_scenes(model, fine, order)
    perceive_s = time.perf_counter() - t0
    baseline = count_scenes(base, rendered(base.input_size), order) if base is not None else None
    index = {s.id: i for i, s in enumerate(ds.scenes)}
    rows = []                  # (level, scene, predicted, visible, answer, smallest countable target's area, baseline's)
    for q in ds.select(split=a.split, types=["counting"]):
        i = index[q.scene_id]
        _, visible, classes, _ = scenes[i]
        c = 1 + ds.classes.index(q.classes[0])
        areas = visible[(classes == c) & (visible >= COUNTABLE_PX)]
        rows.append((LEVELS.index(ds.scenes[i].difficulty), i, int(counted[i][c - 1]), len(areas), int(q.answer),
                     float(areas.min()) if len(areas) else float("nan"), int(baseline[i][c - 1]) if baseline else -1))
    t = torch.tensor(rows, dtype=torch.float64)
    report = {"perception": a.perception, "baseline": a.baseline, "dataset": a.dataset, "split": a.split, "step": meta.get("step"),
              "render": a.render,
              "counting": model.counting,
              "render_s": round(render_s, 1), "perceive_ms_per_image": round(1000 * perceive_s / len(order), 1), "levels": {}}
    print(f"{a.perception} (step {meta.get('step')}) on {a.dataset} {a.split}: {len(order)} first images "
          f"({report['perceive_ms_per_image']} ms each), {len(rows)} COUNTING questions")
    for lv, level in enumerate(LEVELS):
        m = t[:, 0] == lv
        if not m.any():
            continue
        right = (t[m, 2] == t[m, 3]).double()
        mean, lo, hi, n_scenes = scene_bootstrap_ci95(right, t[m, 1].long())
        answer = float((t[m, 2] == t[m, 4]).double().mean())
        perfect = float((t[m, 3] == t[m, 4]).double().mean())
        too_many = float((t[m, 2] > t[m, 3]).double().mean())
        too_few = float((t[m, 2] < t[m, 3]).double().mean())
        report["levels"][level] = {"count_equals_visible": mean, "low": lo, "high": hi, "questions": int(m.sum()),
                                   "scenes": n_scenes, "count_equals_answer": answer, "perfect_counter_equals_answer": perfect,
                                   "too_many": too_many, "too_few": too_few}
        print(f"  {level:6s} {int(m.sum()):4d} questions, {n_scenes:3d} scenes: count = visible {mean:.3f} "
              f"[{lo:.3f}, {hi:.3f}] (too many {too_many:.3f}, too few {too_few:.3f})  = answer {answer:.3f}  "
              f"(perfect counter = answer {perfect:.3f})")
        if baseline is not None:
            diff = right - (t[m, 6] == t[m, 3]).double()
            d, dlo, dhi, _ = scene_bootstrap_ci95(diff, t[m, 1].long())
            report["levels"][level]["minus_baseline"] = {"mean": d, "low": dlo, "high": dhi}
            print(f"         − baseline ({a.baseline}): {d:+.3f} [{dlo:+.3f}, {dhi:+.3f}]")
    bins = {}
    for low, high in AREA_BINS:
        m = (t[:, 5] >= low) & (t[:, 5] < high)
        if m.any():
            bins[f"{low}-{high}"] = {"count_equals_visible": float((t[m, 2] == t[m, 3]).double().mean()), "questions": int(m.sum())}
    m = t[:, 3] == 0
    bins["no countable target"] = {"count_equals_visible": float((t[m, 2] == 0).double().mean()), "questions": int(m.sum())}
    report["by_smallest_visible_px"] = bins
    print("  by the smallest countable target's visible px: " + ", ".join(
        f"{k}: {v['count_equals_visible']:.3f} (n={v['questions']})" for k, v in bins.items()))
    if a.json:
        write_atomic(Path(a.json), json.dumps(report, indent=1))


if __name__ == "__main__":
    main()

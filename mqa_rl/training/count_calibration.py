"""How well a counting perception counts, on held-out frames of whole pretraining scenes: the share of (frame, class in
its scene) pairs whose count equals the perfect counter's (objects with >= 20 visible pixels), overall and by level.
It picks the checkpoint a perception run keeps, and the counting settings (vote radius, suppression window,
probability floor, mass threshold; the density's rounding point) written into the file: chosen where the rule is
judged, not on the test questions."""

from __future__ import annotations

import itertools

import torch

from mqa_rl import keys
from mqa_rl.data.dataset import LEVELS
from mqa_rl.losses.perception import countable_counts
from mqa_rl.modules.answering import vote_counting
from mqa_rl.modules.answering.perception import CountingPerception

# the counting settings tried on held-out pretraining scenes (vote_counting.DEFAULT_COUNTING: what they mean)
CALIBRATION_GRID = {"radius": (2.5, 4.0), "nms": (5, 9), "min_prob": (0.05, 0.3), "min_px": (12, 16, 20, 28, 36),
                    "round_at": (0.3, 0.4, 0.5, 0.6, 0.7)}


def true_counts(frames, num_classes: int) -> torch.Tensor:
    """int64 [N, K-1]: objects of each class with ≥ COUNTABLE_PX visible pixels (the perfect counter)."""
    return countable_counts(frames.get(keys.FRAME_VISIBLE), frames.get(keys.OBJECT_CLASSES), num_classes).long()


def count_accuracy_table(pred: torch.Tensor, frames) -> dict[str, float]:
    """Share of (frame, class present in its scene) pairs whose count ``pred`` [N, K-1] is right, overall and by level."""
    k = pred.shape[1] + 1
    present = torch.nn.functional.one_hot(frames.get(keys.OBJECT_CLASSES), k)[..., 1:].amax(1).bool()
    right = (pred == true_counts(frames, k)) & present
    levels = frames.get(keys.LEVEL)
    out = {"val/count_accuracy": (right.sum() / present.sum()).item()}
    for i, name in enumerate(LEVELS):
        if (levels == i).any():
            out[f"val/count_accuracy_{name}"] = (right[levels == i].sum() / present[levels == i].sum()).item()
    return out


@torch.no_grad()
def predictions(model: CountingPerception, frames, device, batch_size: int = 64):
    """(class probabilities, votes, density) of every frame, on the CPU."""
    model.eval()
    depth = frames.get(keys.DEPTH) if model.depth else None
    out = [model.predict(frames.get(keys.RGB)[s:s + batch_size].to(device),
                         None if depth is None else depth[s:s + batch_size].to(device))
           for s in range(0, frames.shape[0], batch_size)]
    model.train()
    return tuple(torch.cat([o[i].float().cpu() for o in out]) for i in range(3))


def count_accuracy(model: CountingPerception, frames, device) -> dict[str, float]:
    """``count_accuracy_table`` of the model's counts with its own counting settings, and (``val/density_*``)
    of its density readout rounded to the nearest count."""
    probs, votes, density = predictions(model, frames, device)
    out = count_accuracy_table(vote_counting.counts(probs, votes, density, model.cell_px, **model.counting), frames)
    dens = count_accuracy_table(vote_counting.density_counts(vote_counting.expected_counts(probs, density)), frames)
    return {**out, **{k.replace("val/", "val/density_"): v for k, v in dens.items()}}


def calibrate_counting(model: CountingPerception, frames, device) -> tuple[dict, dict, list[dict]]:
    """The counting settings (``CALIBRATION_GRID``) under which the model counts the most (frame, class present)
    pairs of ``frames`` (held-out pretraining scenes) right, their accuracy row, and every setting's."""
    probs, votes, density = predictions(model, frames, device)
    tried = []
    grid = CALIBRATION_GRID
    for radius, nms, min_prob in itertools.product(grid["radius"], grid["nms"], grid["min_prob"]):
        masses = vote_counting.clusters(probs, votes, model.cell_px, radius=radius, nms=nms, min_prob=min_prob)
        for min_px in grid["min_px"]:
            setting = {**model.counting, "radius": radius, "nms": nms, "min_prob": min_prob, "min_px": min_px, "readout": "votes"}
            tried.append({**setting, **count_accuracy_table(vote_counting.counts_of(masses, min_px), frames)})
    expected = vote_counting.expected_counts(probs, density)
    for round_at in grid["round_at"]:
        setting = {**model.counting, "readout": "density", "round_at": round_at}
        tried.append({**setting, **count_accuracy_table(vote_counting.density_counts(expected, round_at), frames)})
    best = max(tried, key=lambda r: r["val/count_accuracy"])
    return {k: best[k] for k in vote_counting.DEFAULT_COUNTING}, best, tried

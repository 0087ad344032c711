"""Counting instances from the perception's class probabilities and centre votes.

For every class, each output cell the class wins (its most probable class) casts its expected visible
area (class probability × the 224-px pixels the cell covers) at the place it votes for (cell centre +
predicted offset). Only the winning class votes: a cell's vote points at the centre of the object
covering most of it, so a minority class's share would land on another object's centre and make a
spurious cluster there (with the true class fractions and true votes of held-out pretraining frames,
every class voting counted 0.41 of the (frame, class) pairs right, the winner alone 0.95-0.97). Votes pile up
at the objects' centres; peaks of the vote map (non-maximum suppression over ``nms`` cells) are the
candidate objects, every vote joins its nearest peak within ``radius`` cells, and a cluster's mass
is then the visible area of one object in the perfect counter's pixels. An object counts when its
mass reaches ``min_px`` (20: ``COUNTABLE_PX``, the perfect counter's rule).

``count_features`` gives, per class, what the VQA head reads: the count (one-hot, 0 … ``MAX_COUNT``,
the last bin meaning "that many or more"), the ``TOP`` largest cluster masses (log-scaled, so that a
head can set its own threshold) and the class's visible area; plus one image-wide entry (row 0), the
number of counted objects of every class (how crowded the bin looks: a difficulty signal read from the image).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from mqa_rl.transforms.episode_stats import COUNTABLE_PX

MAX_COUNT = 6              # count one-hot bins 0 … 6 (6 = six or more)
TOP = 6                    # largest cluster masses kept per class
FEATURES = (MAX_COUNT + 1) + TOP + 1          # per class: count one-hot, top masses, area
PEAK_FLOOR = 4.0           # a peak needs this much smoothed vote mass (px) to be a candidate at all
# How clusters are formed and counted; a perception file carries its own, chosen on held-out pretraining
# scenes (recipes/train_perception.py calibrates them): radius (cells) within which a vote joins a peak,
# the non-maximum suppression window (cells), the class probability below which a cell does not vote,
# and the cluster mass (px) from which an object counts (the rule's 20 px, or what the predicted masses
# need to meet it).
DEFAULT_COUNTING = {"radius": 2.5, "nms": 5, "min_prob": 0.05, "min_px": COUNTABLE_PX}


def clusters(probs: torch.Tensor, votes: torch.Tensor, cell_px: float, *, radius: float = DEFAULT_COUNTING["radius"],
             nms: int = DEFAULT_COUNTING["nms"], min_prob: float = DEFAULT_COUNTING["min_prob"]):
    """Per image and class the masses (224-px) of its vote clusters.

    probs [B, K, s, s] (class 0 = background is skipped), votes [B, 2, s, s] (dy, dx in cells).
    Returns a list over images of lists over classes 1 … K-1 of float tensors of cluster masses."""
    b, k, s, _ = probs.shape
    ys, xs = torch.meshgrid(torch.arange(s, dtype=probs.dtype), torch.arange(s, dtype=probs.dtype), indexing="ij")
    out = []
    for i in range(b):
        ty = (ys + votes[i, 0]).clamp(0, s - 1)
        tx = (xs + votes[i, 1]).clamp(0, s - 1)
        cell = (ty.round() * s + tx.round()).long().flatten()                    # [s*s] where each cell votes
        owned = probs[i].argmax(0).flatten() == torch.arange(1, k)[:, None]        # [K-1, s*s] cells a class wins
        mass = probs[i, 1:].flatten(1) * cell_px * owned * (probs[i, 1:].flatten(1) >= min_prob)
        hist = torch.zeros(k - 1, s * s, dtype=probs.dtype).index_add_(1, cell, mass).view(k - 1, 1, s, s)
        smooth = F.avg_pool2d(hist, 3, 1, 1, count_include_pad=False) * 9
        peaks = (smooth == F.max_pool2d(smooth, int(nms), 1, int(nms) // 2)) & (smooth >= PEAK_FLOOR)
        per_class = []
        vote_pos = torch.stack([ty.flatten(), tx.flatten()], -1)                  # [s*s, 2]
        for c in range(k - 1):
            where = peaks[c, 0].nonzero().to(probs.dtype)                         # [P, 2]
            if where.numel() == 0:
                per_class.append(torch.zeros(0, dtype=probs.dtype))
                continue
            active = mass[c] > 0
            d = torch.cdist(vote_pos[active], where)                              # [V, P]
            nearest, which = d.min(1)
            keep = nearest <= radius
            per_class.append(torch.zeros(len(where), dtype=probs.dtype).index_add_(0, which[keep], mass[c][active][keep]))
        out.append(per_class)
    return out


def counts(probs: torch.Tensor, votes: torch.Tensor, cell_px: float, min_px: float = COUNTABLE_PX, **kwargs) -> torch.Tensor:
    """int64 [B, K-1]: objects of each class (classes 1 … K-1) whose cluster holds ≥ ``min_px`` visible px."""
    return counts_of(clusters(probs, votes, cell_px, **kwargs), min_px)


def counts_of(masses, min_px: float = COUNTABLE_PX) -> torch.Tensor:
    """int64 [B, K-1] from ``clusters``' masses: the clusters of each class holding ≥ ``min_px``."""
    return torch.tensor([[int((m >= min_px).sum()) for m in per_class] for per_class in masses], dtype=torch.int64)


def count_features(probs: torch.Tensor, votes: torch.Tensor, cell_px: float, min_px: float = COUNTABLE_PX,
                   **kwargs) -> torch.Tensor:
    """float [B, K, FEATURES] of the perception's output: ``features_from_masses`` of its vote clusters,
    with each class's area the sum of its probabilities (px)."""
    area = probs[:, 1:].flatten(2).sum(-1) * cell_px                               # [B, K-1] px
    return features_from_masses(clusters(probs, votes, cell_px, **kwargs), area, min_px)


def features_from_masses(masses, area: torch.Tensor, min_px: float = COUNTABLE_PX) -> torch.Tensor:
    """float [B, K, FEATURES] from per image and class (1 … K-1) the objects' visible masses (px) and the
    classes' areas [B, K-1]: row c ≥ 1 the class c (count one-hot, top masses, area), aligned with the
    class channels; row 0 the image-wide entry: the number of counted objects of every class (/ 50, first
    entry). The true masses (every object's visible pixels) give what a perfect perception would."""
    b, k = area.shape[0], area.shape[1] + 1
    feats = torch.zeros(b, k, FEATURES, dtype=torch.float32)
    for i, per_class in enumerate(masses):
        total = 0
        for c, m in enumerate(per_class):
            n = int((m >= min_px).sum())
            total += n
            feats[i, c + 1, min(n, MAX_COUNT)] = 1.0
            top = torch.sort(m, descending=True).values[:TOP]
            feats[i, c + 1, MAX_COUNT + 1:MAX_COUNT + 1 + len(top)] = torch.log1p(top / min_px).float()
            feats[i, c + 1, -1] = math.log1p(float(area[i, c]) / min_px)
        feats[i, 0, 0] = total / 50.0
    return feats

"""Counting instances from the perception's class probabilities and centre votes, or its density.

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

The density readout (``readout="density"``) needs no clusters: a class's expected count is the sum over
cells of density × class probability, and the count rounds it up from ``round_at`` (0.5: to the nearest).

``count_features`` gives, per class, what the VQA head reads: the count under the readout (one-hot,
0 … ``MAX_COUNT``, the last bin meaning "that many or more"), the ``TOP`` largest cluster masses
(log-scaled, so that a head can set its own threshold), the class's visible area and its expected count
from the density; plus one image-wide entry (row 0), the number of counted objects of every class (how
crowded the bin looks: a difficulty signal read from the image). ``trainable_count_features`` gives the same
numbers with gradients, so that the VQA's answer loss can fine-tune the perception under it.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from mqa_rl.transforms.episode_stats import COUNTABLE_PX

MAX_COUNT = 6              # count one-hot bins 0 … 6 (6 = six or more)
TOP = 6                    # largest cluster masses kept per class
FEATURES = (MAX_COUNT + 1) + TOP + 2          # per class: count one-hot, top masses, area, expected count
PEAK_FLOOR = 4.0           # a peak needs this much smoothed vote mass (px) to be a candidate at all
# How clusters are formed and counted; a perception file carries its own, chosen on held-out pretraining
# scenes (recipes/train_perception.py calibrates them): radius (cells) within which a vote joins a peak,
# the non-maximum suppression window (cells), the class probability below which a cell does not vote,
# and the cluster mass (px) from which an object counts (the rule's 20 px, or what the predicted masses
# need to meet it); and which readout counts (``READOUTS``) with the density's rounding point.
READOUTS = ("votes", "density")
DEFAULT_COUNTING = {"radius": 2.5, "nms": 5, "min_prob": 0.05, "min_px": COUNTABLE_PX, "readout": "votes", "round_at": 0.5}


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


def expected_counts(probs: torch.Tensor, density: torch.Tensor) -> torch.Tensor:
    """float [B, K-1]: the density's mass of each class (1 … K-1): Σ over cells of density × class probability."""
    return (probs[:, 1:] * density).flatten(2).sum(-1)


def density_counts(expected: torch.Tensor, round_at: float = DEFAULT_COUNTING["round_at"]) -> torch.Tensor:
    """int64 counts from ``expected_counts``: n counts from an expected n - 1 + ``round_at``."""
    return torch.floor(expected + 1.0 - round_at).clamp_min(0).long()


def counts(probs: torch.Tensor, votes: torch.Tensor, density: torch.Tensor, cell_px: float, *,
           readout: str = DEFAULT_COUNTING["readout"], min_px: float = COUNTABLE_PX,
           round_at: float = DEFAULT_COUNTING["round_at"], **cluster_settings) -> torch.Tensor:
    """int64 [B, K-1]: objects of each class (classes 1 … K-1) under ``readout``: vote clusters holding
    ≥ ``min_px`` visible px, or the rounded density mass."""
    masses = clusters(probs, votes, cell_px, **cluster_settings) if readout == "votes" else None
    return read_counts(readout, expected_counts(probs, density), masses, min_px, round_at)


def read_counts(readout: str, expected: torch.Tensor, masses, min_px: float, round_at: float) -> torch.Tensor:
    """int64 [B, K-1] under ``readout`` from the density's expected counts or the vote clusters' masses."""
    if readout == "density":
        return density_counts(expected, round_at)
    if readout != "votes":
        raise ValueError(f"unknown readout {readout!r}; known: {list(READOUTS)}")
    return counts_of(masses, min_px)


def counts_of(masses, min_px: float = COUNTABLE_PX) -> torch.Tensor:
    """int64 [B, K-1] from ``clusters``' masses: the clusters of each class holding ≥ ``min_px``."""
    return torch.tensor([[int((m >= min_px).sum()) for m in per_class] for per_class in masses], dtype=torch.int64)


def count_features(probs: torch.Tensor, votes: torch.Tensor, density: torch.Tensor, cell_px: float, *,
                   readout: str = DEFAULT_COUNTING["readout"], min_px: float = COUNTABLE_PX,
                   round_at: float = DEFAULT_COUNTING["round_at"], **cluster_settings) -> torch.Tensor:
    """float [B, K, FEATURES] of the perception's output: ``features_from_masses`` of its vote clusters,
    with each class's area the sum of its probabilities (px), its expected count from the density, and
    the count under ``readout``."""
    area = probs[:, 1:].flatten(2).sum(-1) * cell_px                               # [B, K-1] px
    expected = expected_counts(probs, density)
    masses = clusters(probs, votes, cell_px, **cluster_settings)
    counted = read_counts(readout, expected, masses, min_px, round_at)
    return features_from_masses(masses, area, min_px, expected=expected, counted=counted)


def trainable_count_features(probs: torch.Tensor, votes: torch.Tensor, density: torch.Tensor, cell_px: float, *,
                             min_px: float = COUNTABLE_PX, round_at: float = DEFAULT_COUNTING["round_at"],
                             **settings) -> torch.Tensor:
    """``count_features`` in the forward pass, with straight-through gradients to the class probabilities and
    the density: the count one-hot passes the gradient of a soft one-hot (linear between the two counts the
    expected count lies between, on the density's rounding scale), the area and the expected count their own,
    the image-wide entry that of the expected counts' sum. The vote-cluster masses pass none (clustering is
    not differentiable). Equal to ``count_features`` in value, so a frozen head starts fine-tuning exactly."""
    with torch.no_grad():
        hard = count_features(probs.detach(), votes.detach(), density.detach(), cell_px, min_px=min_px,
                              round_at=round_at, **settings)
    area = probs[:, 1:].flatten(2).sum(-1) * cell_px
    expected = expected_counts(probs, density)
    position = (expected + 0.5 - round_at).clamp(0.0, float(MAX_COUNT))          # its rounding gives the count
    bins = torch.arange(MAX_COUNT + 1, dtype=position.dtype, device=position.device)
    soft_count = (1.0 - (position.unsqueeze(-1) - bins).abs()).clamp_min(0.0)    # [B, K-1, MAX_COUNT + 1]
    b, k1 = expected.shape
    per_class = torch.cat([soft_count, torch.zeros(b, k1, TOP, dtype=soft_count.dtype),
                           torch.log1p(area / min_px).unsqueeze(-1), expected.unsqueeze(-1)], -1)
    image_wide = F.pad((expected.sum(-1, keepdim=True) / 50.0).unsqueeze(1), (0, FEATURES - 1))
    soft = torch.cat([image_wide, per_class], 1)
    return hard + (soft - soft.detach())


def features_from_masses(masses, area: torch.Tensor, min_px: float = COUNTABLE_PX, *,
                         expected: torch.Tensor | None = None, counted: torch.Tensor | None = None) -> torch.Tensor:
    """float [B, K, FEATURES] from per image and class (1 … K-1) the objects' visible masses (px), the
    classes' areas [B, K-1] and, optionally, expected counts and counts [B, K-1] (default: the masses
    ≥ ``min_px``): row c ≥ 1 the class c (count one-hot, top masses, area, expected count), aligned with
    the class channels; row 0 the image-wide entry: the number of counted objects of every class (/ 50,
    first entry). The true masses (every object's visible pixels) give what a perfect perception would."""
    b, k = area.shape[0], area.shape[1] + 1
    if counted is None:
        counted = counts_of(masses, min_px)
    if expected is None:
        expected = counted.float()
    feats = torch.zeros(b, k, FEATURES, dtype=torch.float32)
    for i, per_class in enumerate(masses):
        for c, m in enumerate(per_class):
            feats[i, c + 1, min(int(counted[i, c]), MAX_COUNT)] = 1.0
            top = torch.sort(m, descending=True).values[:TOP]
            feats[i, c + 1, MAX_COUNT + 1:MAX_COUNT + 1 + len(top)] = torch.log1p(top / min_px).float()
            feats[i, c + 1, -2] = math.log1p(float(area[i, c]) / min_px)
            feats[i, c + 1, -1] = float(expected[i, c])
        feats[i, 0, 0] = float(counted[i].sum()) / 50.0
    return feats

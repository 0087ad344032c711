"""The counting perception's loss, with its targets made from the simulator's object maps.

* class: each output cell's class *fractions* (of its input pixels) as a soft target of a
  cross-entropy, so that probability × the cell's pixels is the visible area the cell holds;
* votes: for every cell showing an object, the offset from the cell to the centre of the visible
  pixels of the object covering most of it, weighted by that share (smooth L1, in cells), as Panoptic-DeepLab regresses instance centres;
* density: every countable object (≥ 20 visible px in the render) spreads a unit mass over its visible
  cells (squared error summed over an image's cells), and each class's count read from it (density ×
  class probability, summed) meets the perfect counter's count of that class (smooth L1): the
  measured quantity itself is a loss term.

Trained on crops of a frame (``recipes/train_perception.py train.crop``), an object cut by the crop keeps the mass
per cell of the whole frame (its unit over its pixels in the *uncropped* map, ``SLOT_AREA``), and each class's count
target is the share of its countable objects' pixels inside the crop: the targets of a crop are the crop of the
whole frame's targets.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from tensordict import TensorDict
from torch import nn

from mqa_rl import keys
from mqa_rl.data.scenes import MAX_OBJECTS
from mqa_rl.transforms.episode_stats import COUNTABLE_PX


def countable_counts(visible_area: torch.Tensor, object_classes: torch.Tensor, num_classes: int) -> torch.Tensor:
    """float [B, K-1]: objects of each class (1 … K-1) with ≥ ``COUNTABLE_PX`` visible render pixels (the
    perfect counter), from visible areas [B, 50] and slot classes [B, 50]."""
    countable = (visible_area >= COUNTABLE_PX).float()
    return torch.einsum("bn,bnk->bk", countable, F.one_hot(object_classes, num_classes).float())[:, 1:]


def slot_pixels(object_map: torch.Tensor) -> torch.Tensor:
    """float [B, 50]: each slot's pixels in object maps uint8 [B, S, S] (0 = bin, 1 + slot). One bincount over the
    batch (a one-hot of a 224-px batch would allocate ~0.6 GB on every training step)."""
    b, n = object_map.shape[0], MAX_OBJECTS + 1
    ids = object_map.long().flatten(1) + n * torch.arange(b, device=object_map.device)[:, None]
    return torch.bincount(ids.flatten(), minlength=b * n).view(b, n)[:, 1:].float()


def random_crop(size: int, *images: torch.Tensor) -> tuple[tuple[torch.Tensor, ...], torch.Tensor]:
    """The same random ``size`` × ``size`` window of each frame's images (rgb, object map, depth: [B, ..., S, S];
    the object map the second), at even offsets so that its output cells are the whole frame's, and each slot's
    pixels in the uncropped object map [B, 50] (``keys.SLOT_AREA``: a cut object keeps its whole mass per cell)."""
    omap = images[1]
    b, full = omap.shape[0], omap.shape[-1]
    slot_area = slot_pixels(omap)
    dev = omap.device
    ys = torch.randint((full - size) // 2 + 1, (b,), device=dev) * 2
    xs = torch.randint((full - size) // 2 + 1, (b,), device=dev) * 2
    rows = (ys[:, None] + torch.arange(size, device=dev))[:, :, None]           # [B, size, 1]
    cols = (xs[:, None] + torch.arange(size, device=dev))[:, None, :]           # [B, 1, size]
    batch = torch.arange(b, device=dev)[:, None, None]
    crops = tuple(x[batch, ..., rows, cols].movedim(3, 1) if x.dim() == 4 else x[batch, rows, cols] for x in images)
    return crops, slot_area


def crop_counts(visible_area: torch.Tensor, object_classes: torch.Tensor, num_classes: int, inside: torch.Tensor,
                slot_area: torch.Tensor) -> torch.Tensor:
    """float [B, K-1]: ``countable_counts`` of a crop: each countable object weighs the share of its pixels that
    lie inside the crop (``inside`` / ``slot_area``: pixels of each slot [B, 50] in the crop / in the whole map)."""
    countable = (visible_area >= COUNTABLE_PX).float() * inside / slot_area.clamp_min(1.0)
    return torch.einsum("bn,bnk->bk", countable, F.one_hot(object_classes, num_classes).float())[:, 1:]


def perception_targets(object_map: torch.Tensor, object_classes: torch.Tensor, visible_area: torch.Tensor,
                       num_classes: int, out_size: int, slot_area: torch.Tensor | None = None):
    """(class fractions [B, K, s, s], offsets [B, 2, s, s], vote weight [B, s, s]: the share of the
    cell its main object covers, density [B, 1, s, s]: the countable objects' unit masses over their
    cells) from object maps uint8 [B, S, S] (0 = bin, 1 + slot), slot classes int64 [B, 50] and visible
    render areas [B, 50]. ``slot_area`` [B, 50]: each slot's pixels in the uncropped map when ``object_map`` is a crop
    (a cut object's cells keep the whole object's mass per cell); None: the map is the whole frame."""
    b, size = object_map.shape[0], object_map.shape[-1]
    pool = size // out_size
    omap = object_map.long()
    slots = F.one_hot(omap, MAX_OBJECTS + 1).permute(0, 3, 1, 2).float()            # [B, 51, S, S]
    slot_frac = F.avg_pool2d(slots, pool)                                             # [B, 51, s, s]
    lut = torch.cat([torch.zeros(b, 1, dtype=torch.int64, device=omap.device), object_classes], 1)   # slot 0 = bin
    cls_onehot = F.one_hot(lut, num_classes).float()                                  # [B, 51, K]
    class_frac = torch.einsum("bnyx,bnk->bkyx", slot_frac, cls_onehot)
    # centre of each object's visible pixels, in output cells
    ys = (torch.arange(size, device=omap.device, dtype=torch.float32) + 0.5) / pool - 0.5
    area = slots.sum((2, 3)).clamp_min(1e-6)                                          # [B, 51]
    cy = (slots.sum(3) * ys).sum(-1) / area
    cx = (slots.sum(2) * ys).sum(-1) / area
    share, owner = slot_frac[:, 1:].max(1)                                            # the cell's main object
    owner = owner + 1
    grid = torch.arange(out_size, device=omap.device, dtype=torch.float32)
    ty = torch.gather(cy, 1, owner.flatten(1)).view_as(share) - grid[:, None]
    tx = torch.gather(cx, 1, owner.flatten(1)).view_as(share) - grid[None, :]
    weight = share                                                                    # 0 where no object shows
    countable = torch.cat([torch.zeros_like(visible_area[:, :1]), visible_area], 1) >= COUNTABLE_PX   # [B, 51]
    whole = area if slot_area is None else torch.cat([area[:, :1], slot_area.float()], 1)
    unit = countable.float() * pool * pool / whole.clamp_min(1.0)                     # mass per cell it fills
    density = torch.einsum("bnyx,bn->byx", slot_frac, unit).unsqueeze(1)
    return class_frac, torch.stack([ty, tx], 1), weight, density


class PerceptionLoss(nn.Module):
    """TensorDict [B] (``OBJECT_MAP``, ``OBJECT_CLASSES``, ``FRAME_VISIBLE``; ``SLOT_AREA`` for crops) and the model's standardised
    inputs → losses, the class accuracy of object cells and the density's count error. ``model``: a
    ``CountingPerception``."""

    def __init__(self, model, vote_weight: float = 0.5, density_weight: float = 1.0):
        super().__init__()
        self.model = model
        self.vote_weight = float(vote_weight)
        self.density_weight = float(density_weight)

    def forward(self, batch: TensorDict, inputs: torch.Tensor) -> TensorDict:
        logits, votes, density = self.model(inputs)
        classes, visible = batch.get(keys.OBJECT_CLASSES), batch.get(keys.FRAME_VISIBLE).float()
        omap, slot_area = batch.get(keys.OBJECT_MAP), batch.get(keys.SLOT_AREA, None)
        frac, offsets, weight, target = perception_targets(omap, classes, visible, self.model.num_classes,
                                                           logits.shape[-1], slot_area)     # a crop's cells too
        if slot_area is None:
            counted = countable_counts(visible, classes, self.model.num_classes)
        else:
            counted = crop_counts(visible, classes, self.model.num_classes, slot_pixels(omap), slot_area)
        loss_class = -(frac * F.log_softmax(logits, 1)).sum(1).mean()
        vote_err = F.smooth_l1_loss(votes, offsets, reduction="none").sum(1)
        loss_votes = (vote_err * weight).sum() / weight.sum().clamp_min(1.0)
        loss_map = (density - target).square().flatten(1).sum(1).mean()
        expected = (logits.softmax(1)[:, 1:] * density).flatten(2).sum(-1)                  # [B, K-1]
        count_err = F.smooth_l1_loss(expected, counted, reduction="none")
        loss_count = count_err.sum(1).mean()
        with torch.no_grad():
            fg = frac[:, 1:].sum(1) >= 0.5
            right = (logits.argmax(1) == frac.argmax(1)) & fg
            accuracy = right.sum() / fg.sum().clamp_min(1)
        return TensorDict({"loss_class": loss_class, "loss_votes": self.vote_weight * loss_votes,
                           "loss_density": self.density_weight * (loss_map + loss_count),
                           "vote_error": (vote_err * weight).sum().detach() / weight.sum().clamp_min(1.0),
                           "count_error": count_err.detach().sum(1).mean(),
                           "class_accuracy": accuracy}, batch_size=[])

    def total(self, td: TensorDict) -> torch.Tensor:
        """The sum the optimiser descends."""
        return td["loss_class"] + td["loss_votes"] + td["loss_density"]

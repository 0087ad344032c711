"""The counting perception's loss, with its targets made from the simulator's object maps.

* class: each output cell's class *fractions* (of its input pixels) as a soft target of a
  cross-entropy, so that probability × the cell's pixels is the visible area the cell holds;
* votes: for every cell showing an object, the offset from the cell to the centre of the visible
  pixels of the object covering most of it, weighted by that share (smooth L1, in cells), as Panoptic-DeepLab regresses instance centres.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from tensordict import TensorDict
from torch import nn

from mqa_rl import keys
from mqa_rl.envs.sapien_bin import MAX_OBJECTS


def perception_targets(object_map: torch.Tensor, object_classes: torch.Tensor, num_classes: int, out_size: int):
    """(class fractions [B, K, s, s], offsets [B, 2, s, s], vote weight [B, s, s]: the share of the
    cell its main object covers) from object maps
    uint8 [B, S, S] (0 = bin, 1 + slot) and slot classes int64 [B, 50]."""
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
    return class_frac, torch.stack([ty, tx], 1), weight


class PerceptionLoss(nn.Module):
    """TensorDict [B] (``RGB`` standardised by the model, ``OBJECT_MAP``, ``OBJECT_CLASSES``) → losses and
    the class accuracy of object cells. ``model``: a ``CountingPerception``."""

    def __init__(self, model, vote_weight: float = 0.5):
        super().__init__()
        self.model = model
        self.vote_weight = float(vote_weight)

    def forward(self, batch: TensorDict, inputs: torch.Tensor) -> TensorDict:
        logits, votes = self.model(inputs)
        frac, offsets, weight = perception_targets(batch.get(keys.OBJECT_MAP), batch.get(keys.OBJECT_CLASSES),
                                                   self.model.num_classes, self.model.out_size)
        loss_class = -(frac * F.log_softmax(logits, 1)).sum(1).mean()
        vote_err = F.smooth_l1_loss(votes, offsets, reduction="none").sum(1)
        loss_votes = (vote_err * weight).sum() / weight.sum().clamp_min(1.0)
        with torch.no_grad():
            fg = frac[:, 1:].sum(1) >= 0.5
            right = (logits.argmax(1) == frac.argmax(1)) & fg
            accuracy = right.sum() / fg.sum().clamp_min(1)
        return TensorDict({"loss_class": loss_class, "loss_votes": self.vote_weight * loss_votes,
                           "vote_error": (vote_err * weight).sum().detach() / weight.sum().clamp_min(1.0),
                           "class_accuracy": accuracy}, batch_size=[])

"""Augmentations of the perception's labelled frames: new piles out of the ones rendered.

* ``dihedral_pair``: the same random rotation / mirror image of a frame's rgb and object map (the bin seen
  from above is symmetric).
* ``copy_paste``: objects cut out of another frame of the batch, with their pixels and labels, laid over
  this frame at the same place (Simple Copy-Paste, Ghiasi et al., CVPR 2021). What they cover is
  hidden: the covered objects lose those pixels, so the perfect counter's rule (≥ 20 visible px)
  is re-read from the edited object map, exactly. A perception that learns its piles (0.87 of its
  own piles' (image, class) pairs counted right against 0.67 of fresh ones, docs/perception.md) sees
  a new pile at every step.
"""

from __future__ import annotations

import torch

from mqa_rl.transforms.dihedral import DIHEDRAL, dihedral


def dihedral_pair(rgb: torch.Tensor, omap: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The same random dihedral transform of each frame's rgb [B, 3, S, S] and object map [B, S, S]."""
    k = torch.randint(DIHEDRAL, (rgb.shape[0],))
    rgb, omap = rgb.clone(), omap.clone()
    for t in k.unique().tolist():
        rgb[k == t] = dihedral(rgb[k == t], t)
        omap[k == t] = dihedral(omap[k == t], t)
    return rgb, omap


def copy_paste(rgb: torch.Tensor, omap: torch.Tensor, classes: torch.Tensor, visible: torch.Tensor, *,
               prob: float, max_objects: int, generator: torch.Generator | None = None):
    """With probability ``prob`` per frame, lay 1 … ``max_objects`` visible objects of another frame of the batch
    over it. rgb uint8 [B, 3, S, S], object map uint8 [B, S, S] (0 = bin, 1 + slot), slot classes int64 [B, N],
    visible areas float [B, N] (render pixels) → the edited four (copies). A pasted object takes a free slot
    (none left: not pasted); every slot's visible area is rescaled by the share of its pixels still showing
    (exact at the render's size; a slot with no pixel at this size keeps its area), a pasted one's is its donor's."""
    if not 0.0 <= prob <= 1.0 or max_objects < 1:
        raise ValueError(f"copy_paste needs prob in [0, 1] and max_objects ≥ 1, got {prob}, {max_objects}")
    b = omap.shape[0]
    if b < 2 or prob == 0.0:
        return rgb, omap, classes, visible
    rgb, omap, classes, visible = rgb.clone(), omap.clone(), classes.clone(), visible.clone().float()
    slots = classes.shape[1]
    donors = (torch.arange(b) + torch.randint(1, b, (b,), generator=generator)) % b        # never the frame itself
    chosen = torch.rand(b, generator=generator) < prob
    for i in chosen.nonzero().flatten().tolist():
        j = int(donors[i])
        before = torch.bincount(omap[i].flatten().long(), minlength=slots + 1)[1:].float()
        shown = torch.bincount(omap[j].flatten().long(), minlength=slots + 1)[1:]
        candidates = (shown > 0).nonzero().flatten()
        free = (classes[i] == 0).nonzero().flatten()
        n = min(int(torch.randint(1, max_objects + 1, (1,), generator=generator)), len(candidates), len(free))
        if n == 0:
            continue
        picked = candidates[torch.randperm(len(candidates), generator=generator)[:n]]
        for src, dst in zip(picked.tolist(), free[:n].tolist()):
            mask = omap[j] == src + 1
            rgb[i][:, mask] = rgb[j][:, mask]
            omap[i][mask] = dst + 1
            classes[i, dst] = classes[j, src]
        after = torch.bincount(omap[i].flatten().long(), minlength=slots + 1)[1:].float()
        keep = torch.where(before > 0, after / before.clamp_min(1.0), torch.ones_like(after))
        visible[i] = visible[i] * keep
        visible[i, free[:n]] = visible[j, picked] * after[free[:n]] / shown[picked].float()
    return rgb, omap, classes, visible

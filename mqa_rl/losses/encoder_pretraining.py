"""``EncoderPretrainLoss``: EQA's multi-task pretraining of the VQA's CNN on our renders, as a TorchRL
``LossModule``: reconstruct the image (MSE on the standardised rgb), predict the height above the bin
floor (L1, in units of ``depth_scale``) and the class of every pixel (cross-entropy over
background + the dataset's classes), all at the heads' 56 px; and (ours) on the third block's
24 × 24 map, through the encoder's own heads, the class areas of each cell (``class_head``,
cross-entropy against the area fractions) and a density map per class (``density_head``: one unit
of mass in the cell of every object with at least ``min_visible_px`` visible pixels, at its visible
pixels' centroid, optionally spread by a Gaussian of ``density_sigma`` cells; squared error per cell
plus the error of the per-class sums, i.e. the counts).
It also reports the pixel accuracy of the class map on object pixels, the cells' accuracy (their
largest class), how often the rounded density sum equals the count of a class present in the frame
(``count_exact``), and the height error in metres (not differentiated).

Frames come from ``mqa_rl.training.vqa_data.pretraining_frames`` (rgb uint8, depth float16 metres,
class map uint8 [H, W]).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torchrl.objectives import LossModule

from mqa_rl import keys
from mqa_rl.modules.answering.vqa_encoder import FrameEncoder, PretrainHeads, standardise


class EncoderPretrainLoss(LossModule):
    @dataclass
    class _AcceptedKeys:
        """rgb uint8 [B, 3, H, W]; depth [B, 1, H, W] metres; class_map and object_map uint8 [B, H, W]."""

        rgb: NestedKey = keys.RGB
        depth: NestedKey = keys.DEPTH
        class_map: NestedKey = keys.CLASS_MAP
        object_map: NestedKey = keys.OBJECT_MAP

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    out_keys = ["loss_rgb", "loss_height", "loss_class", "loss_cells", "loss_density", "class_accuracy", "cell_accuracy",
                "count_exact", "height_error_m"]

    def __init__(self, encoder: FrameEncoder, heads: PretrainHeads, *, camera_distance: float, depth_scale: float = 0.1,
                 weights: dict | None = None, min_visible_px: int = 20, density_sigma: float = 0.0):
        super().__init__()
        self.encoder = encoder
        self.heads = heads
        self.camera_distance = float(camera_distance)
        self.depth_scale = float(depth_scale)
        self.weights = {"rgb": 1.0, "height": 1.0, "class": 1.0, "cells": 1.0, "density": 1.0, **(weights or {})}
        self.min_visible_px = int(min_visible_px)
        self.density_sigma = float(density_sigma)

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass

    @property
    def in_keys(self):
        return [self.tensor_keys.rgb, self.tensor_keys.depth, self.tensor_keys.class_map, self.tensor_keys.object_map]

    def targets(self, td: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(rgb, height, class) at the heads' size: area-averaged images, nearest-sampled classes."""
        size = self.heads.target_size
        rgb = F.adaptive_avg_pool2d(standardise(td.get(self.tensor_keys.rgb), self.encoder.image_size), size)
        depth = td.get(self.tensor_keys.depth).float()
        height = torch.where(depth > 0, (self.camera_distance - depth) / self.depth_scale, torch.zeros_like(depth))
        height = F.adaptive_avg_pool2d(height, size)
        classes = td.get(self.tensor_keys.class_map).long().unsqueeze(1).float()
        classes = F.interpolate(classes, size=(size, size), mode="nearest").squeeze(1).long()
        return rgb, height, classes

    def cell_targets(self, td: TensorDictBase, size) -> torch.Tensor:
        """[B, K, h, w]: the fraction of each cell's pixels of every class (the map's cells tile the image)."""
        classes = td.get(self.tensor_keys.class_map).long()
        onehot = F.one_hot(classes, self.encoder.num_classes).permute(0, 3, 1, 2).float()
        return F.adaptive_avg_pool2d(onehot, tuple(size))

    def density_targets(self, td: TensorDictBase, size) -> torch.Tensor:
        """[B, K, h, w]: one unit per object with ≥ ``min_visible_px`` visible pixels, in the cell of its
        visible pixels' centroid, in its class's channel."""
        objects = td.get(self.tensor_keys.object_map).long()
        classes = td.get(self.tensor_keys.class_map).long()
        b, height, width = objects.shape
        m = int(objects.max()) + 1
        flat, cls = objects.view(b, -1), classes.view(b, -1)
        ys = torch.arange(height, device=flat.device).repeat_interleave(width).expand(b, -1).float()
        xs = torch.arange(width, device=flat.device).repeat(height).expand(b, -1).float()
        zeros = torch.zeros(b, m, device=flat.device)
        count = zeros.scatter_add(1, flat, torch.ones_like(ys))
        cy = zeros.scatter_add(1, flat, ys) / count.clamp(min=1)
        cx = zeros.scatter_add(1, flat, xs) / count.clamp(min=1)
        cls_of = torch.zeros(b, m, dtype=torch.long, device=flat.device).scatter(1, flat, cls)
        valid = (count >= self.min_visible_px) & (torch.arange(m, device=flat.device) > 0)
        h, w = size
        iy = (cy * h / height).long().clamp(0, h - 1)
        ix = (cx * w / width).long().clamp(0, w - 1)
        target = torch.zeros(b, self.encoder.num_classes * h * w, device=flat.device)
        target.scatter_add_(1, cls_of * (h * w) + iy * w + ix, valid.float())
        return target.view(b, self.encoder.num_classes, h, w)

    def blur(self, density: torch.Tensor) -> torch.Tensor:
        """The per-cell targets spread by a Gaussian of ``density_sigma`` cells (crowd counting's usual
        target: a unit in one cell is a needle to hit); 0 = unchanged."""
        if self.density_sigma <= 0:
            return density
        r = max(1, int(3 * self.density_sigma + 0.5))
        g = torch.exp(-0.5 * (torch.arange(-r, r + 1, device=density.device, dtype=density.dtype) / self.density_sigma) ** 2)
        g = g / g.sum()
        b, k, h, w = density.shape
        x = density.reshape(b * k, 1, h, w)
        x = F.conv2d(F.pad(x, (r, r, 0, 0)), g.view(1, 1, 1, -1))
        x = F.conv2d(F.pad(x, (0, 0, r, r)), g.view(1, 1, -1, 1))
        return x.view(b, k, h, w)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        x = standardise(tensordict.get(self.tensor_keys.rgb), self.encoder.image_size)
        mid, feat = self.encoder.features(x)
        rgb_hat, height_hat, class_logits = self.heads(feat)
        rgb, height, classes = self.targets(tensordict)
        cell_logits, density = self.encoder.heads_of(mid, feat)
        cells = self.cell_targets(tensordict, cell_logits.shape[-2:])
        objects = self.density_targets(tensordict, density.shape[-2:])
        counts, true_counts = density.sum((-2, -1)), objects.sum((-2, -1))
        objects = self.blur(objects)
        b, k = counts.shape
        out = {"loss_rgb": self.weights["rgb"] * F.mse_loss(rgb_hat, rgb),
               "loss_height": self.weights["height"] * F.l1_loss(height_hat, height),
               "loss_class": self.weights["class"] * F.cross_entropy(class_logits, classes),
               "loss_cells": self.weights["cells"] * F.cross_entropy(cell_logits, cells),
               "loss_density": self.weights["density"] * (F.mse_loss(density, objects, reduction="sum") / (b * k)
                                                          + F.l1_loss(counts, true_counts))}
        with torch.no_grad():
            objects = classes > 0
            right = (class_logits.argmax(1) == classes) & objects
            out["class_accuracy"] = right.sum() / objects.sum().clamp(min=1)
            out["cell_accuracy"] = (cell_logits.argmax(1) == cells.argmax(1)).float().mean()
            present = true_counts[:, 1:] > 0                                     # object classes in the frame
            out["count_exact"] = ((counts[:, 1:].round() == true_counts[:, 1:]) & present).sum() / present.sum().clamp(min=1)
            out["height_error_m"] = (height_hat - height).abs().mean() * self.depth_scale
        return TensorDict(out, batch_size=[])

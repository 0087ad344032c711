"""``EncoderPretrainLoss``: EQA's multi-task pretraining of the VQA's CNN on our renders, as a TorchRL
``LossModule``: reconstruct the image (MSE on the standardised rgb), predict the height above the bin
floor (L1, in units of ``depth_scale``) and the class of every pixel (cross-entropy over
background + the dataset's classes), all at the heads' 56 px. It also reports the pixel accuracy of
the class map on object pixels and the height error in metres (not differentiated).

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
from mqa_rl.modules.vqa_encoder import FrameEncoder, PretrainHeads, standardise


class EncoderPretrainLoss(LossModule):
    @dataclass
    class _AcceptedKeys:
        """rgb uint8 [B, 3, H, W]; depth [B, 1, H, W] metres; class_map uint8 [B, H, W]."""

        rgb: NestedKey = keys.RGB
        depth: NestedKey = keys.DEPTH
        class_map: NestedKey = keys.CLASS_MAP

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    out_keys = ["loss_rgb", "loss_height", "loss_class", "class_accuracy", "height_error_m"]

    def __init__(self, encoder: FrameEncoder, heads: PretrainHeads, *, camera_distance: float, depth_scale: float = 0.1,
                 weights: dict | None = None):
        super().__init__()
        self.encoder = encoder
        self.heads = heads
        self.camera_distance = float(camera_distance)
        self.depth_scale = float(depth_scale)
        self.weights = {"rgb": 1.0, "height": 1.0, "class": 1.0, **(weights or {})}

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass

    @property
    def in_keys(self):
        return [self.tensor_keys.rgb, self.tensor_keys.depth, self.tensor_keys.class_map]

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

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        x = standardise(tensordict.get(self.tensor_keys.rgb), self.encoder.image_size)
        rgb_hat, height_hat, class_logits = self.heads(self.encoder(x))
        rgb, height, classes = self.targets(tensordict)
        out = {"loss_rgb": self.weights["rgb"] * F.mse_loss(rgb_hat, rgb),
               "loss_height": self.weights["height"] * F.l1_loss(height_hat, height),
               "loss_class": self.weights["class"] * F.cross_entropy(class_logits, classes)}
        with torch.no_grad():
            objects = classes > 0
            right = (class_logits.argmax(1) == classes) & objects
            out["class_accuracy"] = right.sum() / objects.sum().clamp(min=1)
            out["height_error_m"] = (height_hat - height).abs().mean() * self.depth_scale
        return TensorDict(out, batch_size=[])

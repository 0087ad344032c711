"""The VQA's image encoder: EmbodiedQA's small CNN, and the heads that pretrain it on our renders.

    rgb uint8 [B, 3, 224, 224] → 4 × (conv 5×5, no padding → BN → ReLU → max-pool 2)
                               → 3→8→16→32→32 channels → [B, 32, 10, 10]

EQA pretrained this CNN as a multi-task encoder-decoder (RGB reconstruction, semantic segmentation,
depth) on its renders and froze it for VQA; ``PretrainHeads`` does the same on ours, where the env
gives per-object segmentation (hence per-class labels) and depth. Unlike EQA's FCN decoder, the
heads decode from the 32 × 10 × 10 bottleneck only, with no skip connections from earlier layers:
the VQA reads only the bottleneck, so what the heads must know (which class is where, how high)
has to be in it. Their targets are at a quarter of the input size (56 px: a 6 cm object still
covers ≥ 6 px), which keeps the decoder cheap; the encoder sees the full 224 px image.

Two more heads belong to the encoder itself and read the third block's 24 × 24 map, for the VQA's
``pool="classes"``: ``class_head`` (the class areas inside each cell) and ``density_head`` (a density
map per class: one unit of mass at the centre of every visible object, so that its sum over the
image is the number of visible objects of the class, as crowd counting does). The 10 × 10
bottleneck is too coarse to count: with the true class areas per cell, a VQA answered 0.57 / 0.51 /
0.51 of the COUNTING test questions right from a 10 × 10 map, 0.69 / 0.51 / 0.51 from a 24 × 24 one
(docs/notebook/answering.md, "What limits counting").

An encoder file (``save_encoder`` / ``load_encoder``) holds the encoder's weights and what it was
trained on; ``recipes/pretrain.py part=vqa_encoder`` writes it and ``recipes/train_vqa.py`` loads it
(frozen or fine-tuned).
"""

from __future__ import annotations

import io
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from mqa_rl.files import write_atomic

ENCODER_FORMAT = "mqa_rl.vqa_encoder"
ENCODER_VERSION = 1
RGB_MEAN, RGB_STD = 0.5, 0.25      # fixed standardisation of uint8 images (no dataset statistics to carry)
TARGET_SIZE = 56                   # pretraining targets are predicted at this size


def standardise(rgb: torch.Tensor, size: int) -> torch.Tensor:
    """uint8 rgb [B, 3, H, W] → float [B, 3, size, size], standardised; resized (antialiased) if needed."""
    if rgb.dtype != torch.uint8:
        raise TypeError(f"images must be uint8 (0-255) tensors, got {rgb.dtype}")
    x = rgb.to(torch.float32) / 255.0
    if x.shape[-2:] != (size, size):
        x = F.interpolate(x, size=(size, size), mode="bilinear", align_corners=False, antialias=True)
    return (x - RGB_MEAN) / RGB_STD


class FrameEncoder(nn.Module):
    """EQA's CNN: standardised rgb [B, 3, S, S] → features [B, 32, h, h] (h = 10 for S = 224).

    It also carries ``class_head`` and ``density_head``, 1×1 convs from the third block's map (32 × 24 ×
    24 at 224 px) to per-cell class logits and per-class object densities (background + the dataset's
    classes): pretraining supervises them, and the VQA's ``pool="classes"`` reads them."""

    def __init__(self, channels=(8, 16, 32, 32), image_size: int = 224, num_classes: int = 21, head_width: int = 0):
        super().__init__()
        layers, cin = [], 3
        for cout in channels:
            layers += [nn.Conv2d(cin, cout, 5), nn.BatchNorm2d(cout), nn.ReLU(inplace=True), nn.MaxPool2d(2)]
            cin = cout
        self.net = nn.Sequential(*layers)
        self.channels = tuple(channels)
        self.image_size = int(image_size)
        size = self.image_size
        for _ in channels:
            size = (size - 4) // 2
        if size < 1:
            raise ValueError(f"image_size={image_size} is too small for {len(channels)} conv 5×5 + pool blocks")
        self.out_shape = (cin, size, size)
        self.num_classes = int(num_classes)
        self.head_width = int(head_width)
        if self.head_width < 0:
            raise ValueError(f"head_width must be ≥ 0, got {head_width}")
        head_in = channels[-2]
        self.head_trunk = None
        if self.head_width:        # context for the heads: two 3×3 convs over the map and the upsampled bottleneck
            self.head_trunk = nn.Sequential(nn.Conv2d(channels[-2] + cin, self.head_width, 3, padding=1), nn.ReLU(inplace=True),
                                            nn.Conv2d(self.head_width, self.head_width, 3, padding=1), nn.ReLU(inplace=True))
            head_in = self.head_width
        self.class_head = nn.Conv2d(head_in, self.num_classes, 1)
        self.density_head = nn.Conv2d(head_in, self.num_classes, 1)
        nn.init.constant_(self.density_head.bias, -6.0)      # softplus(-6) ≈ 0.0025: ~1.4 objects per class at first

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)

    def features(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(third block's map [B, 32, 24, 24], bottleneck [B, 32, 10, 10]) of a standardised image."""
        mid = self.net[: 4 * (len(self.channels) - 1)](x)
        return mid, self.net[4 * (len(self.channels) - 1):](mid)

    def heads_of(self, mid: torch.Tensor, bottleneck: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """(class logits, object densities ≥ 0), each [B, K, 24, 24], from the third block's map (and, with
        ``head_width``, the bottleneck: computed from ``mid`` when not given)."""
        if self.head_trunk is not None:
            if bottleneck is None:
                bottleneck = self.net[4 * (len(self.channels) - 1):](mid)
            up = F.interpolate(bottleneck, size=mid.shape[-2:], mode="bilinear", align_corners=False)
            mid = self.head_trunk(torch.cat([mid, up], 1))
        return self.class_head(mid), F.softplus(self.density_head(mid))

    def class_maps(self, x: torch.Tensor) -> torch.Tensor:
        """[B, 2K, 24, 24] of a standardised image: per-cell class log-probabilities, then per-class densities."""
        logits, density = self.heads_of(self.net[: 4 * (len(self.channels) - 1)](x))
        return torch.cat([F.log_softmax(logits, dim=1), density], 1)

    def encode(self, rgb: torch.Tensor) -> torch.Tensor:
        """uint8 rgb [..., 3, H, W] → features [..., C, h, w]."""
        batch = rgb.shape[:-3]
        out = self(standardise(rgb.reshape(-1, *rgb.shape[-3:]), self.image_size))
        return out.reshape(*batch, *out.shape[1:])


class PretrainHeads(nn.Module):
    """Bottleneck [B, C, h, w] → (rgb [B, 3, 56, 56], height [B, 1, 56, 56], class logits [B, K, 56, 56]).

    A shared decoder (conv 3×3 + ReLU, upsample ×2 or to the target size) then three 1×1 heads.
    """

    def __init__(self, in_channels: int = 32, num_classes: int = 21, width: int = 64, target_size: int = TARGET_SIZE):
        super().__init__()
        self.target_size = target_size
        self.num_classes = num_classes
        self.stages = nn.ModuleList([
            nn.Sequential(nn.Conv2d(in_channels, width, 3, padding=1), nn.ReLU(inplace=True)),
            nn.Sequential(nn.Conv2d(width, width, 3, padding=1), nn.ReLU(inplace=True)),
            nn.Sequential(nn.Conv2d(width, width, 3, padding=1), nn.ReLU(inplace=True)),
            nn.Sequential(nn.Conv2d(width, width // 2, 3, padding=1), nn.ReLU(inplace=True)),
        ])
        self.rgb = nn.Conv2d(width // 2, 3, 1)
        self.height = nn.Conv2d(width // 2, 1, 1)
        self.classes = nn.Conv2d(width // 2, num_classes, 1)

    def forward(self, feat: torch.Tensor):
        sizes = [feat.shape[-1], self.target_size // 4, self.target_size // 2, self.target_size]
        x = feat
        for stage, size in zip(self.stages, sizes):
            if x.shape[-1] != size:
                x = F.interpolate(x, size=(size, size), mode="bilinear", align_corners=False)
            x = stage(x)
        return self.rgb(x), self.height(x), self.classes(x)


# ----------------------------------------------------------------------------------------- files
def save_encoder(encoder: FrameEncoder, path: str | Path, meta: dict) -> Path:
    """Write the encoder's weights and ``meta`` (what it was trained on, its validation scores) atomically."""
    path = Path(path)
    blob = {"format": ENCODER_FORMAT, "version": ENCODER_VERSION,
            "config": {"channels": list(encoder.channels), "image_size": encoder.image_size,
                       "num_classes": encoder.num_classes, "head_width": encoder.head_width},
            "state_dict": {k: v.detach().cpu() for k, v in encoder.state_dict().items()}, "meta": dict(meta)}
    buffer = io.BytesIO()
    torch.save(blob, buffer)
    return write_atomic(path, buffer.getvalue())


def load_encoder(path: str | Path) -> tuple[FrameEncoder, dict]:
    """(encoder, meta) from ``save_encoder``'s file. FileNotFoundError / ValueError say what to do."""
    path = Path(path)
    hint = "make one with `python recipes/pretrain.py part=vqa_encoder` (or set vqa.encoder.weights=null to train from scratch)"
    if not path.is_file():
        raise FileNotFoundError(f"no VQA encoder file at {path}: {hint}")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:
        raise ValueError(f"{path} cannot be read as an encoder file ({type(error).__name__}: {error}); it may be "
                         f"truncated: {hint}") from error
    if not isinstance(blob, dict) or blob.get("format") != ENCODER_FORMAT:
        raise ValueError(f"{path} is not a VQA encoder file (format {blob.get('format') if isinstance(blob, dict) else None!r}); {hint}")
    if int(blob.get("version", 0)) > ENCODER_VERSION:
        raise ValueError(f"{path} has encoder format version {blob['version']} > {ENCODER_VERSION}: update mqa_rl")
    cfg = blob["config"]
    encoder = FrameEncoder(tuple(cfg["channels"]), int(cfg["image_size"]), int(cfg.get("num_classes", 21)),
                           int(cfg.get("head_width", 0)))
    try:
        encoder.load_state_dict(blob["state_dict"])
    except RuntimeError as error:
        raise ValueError(f"{path}: the weights do not fit the encoder ({str(error)[:300]}); {hint}") from error
    return encoder, dict(blob.get("meta", {}))

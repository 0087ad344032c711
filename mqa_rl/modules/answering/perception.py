"""The VQA's counting perception: a small U-Net trained on the simulator's labels.

    rgb uint8 [B, 3, 224, 224] → resized to ``image_size`` (112) → encoder (stride 2, 4, 8, 16)
                               → decoder with skips → [B, W, 56, 56]
                               → class logits [B, K, 56, 56]   (K = 1 + dataset classes; 0 = bin)
                               → centre votes  [B, 2, 56, 56]   (offset of each cell to its object's centre)
                               → density       [B, 1, 56, 56]   (each countable object's unit mass, spread
                                                                 over its visible cells)

With ``depth`` the network also reads the camera's depth image (a fourth input channel, ``standardise_depth``):
the height steps between stacked objects are instance boundaries an appearance may not show.

With ``detail`` > 0 a second path reads the full 2 × ``image_size`` render through two stride-2 stages and
adds what it sees to the first stage's 56 × 56 map (small targets are 5-25 px at 112 px, 20-100 px in the
render). Its last layer starts at zero, so a file without it warm-starts one with it.

Counting needs instances, not class areas: a perfect class mask split into connected components
counts 0.80 / 0.61 / 0.48 of the test questions right where a perfect instance counter gets 0.96 /
0.81 / 0.57 (docs/perception.md, "Why instances"): occlusion cuts one object into pieces and touching objects of a
class merge. So every cell also *votes* for the centre of the visible part of its object (as
Panoptic-DeepLab's offset head does): the pieces of one object vote for one place, two touching
objects for two. ``mqa_rl.modules.answering.vote_counting`` turns class probabilities and votes into clusters
whose mass is the object's visible area in 224-px pixels, which is the perfect counter's own rule
(≥ 20 visible px). A third head reads counts without clustering: a density whose mass per countable
object is one (spread over the object's visible cells, as crowd counting spreads a person), so that a
class's count is the sum of density × class probability over the image.

The class head is trained on each cell's class *fractions*, so that a cell's
probability times its 16 px is the visible area it holds, even for objects of a few cells.

A perception file (``save_perception`` / ``load_perception``) holds the weights, the architecture and
what it was trained on; ``recipes/train_perception.py`` writes it.
"""

from __future__ import annotations

import math

from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from mqa_rl.files import load_versioned, refuse_nonfinite, save_versioned
from mqa_rl.modules.answering import vote_counting
from mqa_rl.modules.answering.vqa_encoder import standardise
from mqa_rl.modules.push.imagenet_backbone import EfficientLiteEncoder

PERCEPTION_FORMAT = "mqa_rl.perception"
PERCEPTION_VERSION = 2        # 2: the density head
RENDER_SIZE = 224          # the env's image size: areas and the counting rule are in its pixels
DENSITY_BIAS = -5.0        # softplus(-5) ≈ 0.007 per cell: ~20 objects over 56 × 56 cells at the start
# depth (metres along the view axis; the camera's range is 1.55-2.0 m) standardised with its mean and spread
# over six training piles' renders (1.72 ± 0.125 m; the 10-90 % quantiles 1.55-1.89 m)
DEPTH_MEAN = 1.72
DEPTH_STD = 0.125


BACKBONES = ("unet", "efficientnet_lite0")


def resize_depth(depth: torch.Tensor, size: int) -> torch.Tensor:
    """float depth [B, 1, H, W] (metres) → float [B, 1, size, size], antialiased bilinear as ``standardise``
    resizes rgb (the frame collector stores this, the perception reads it)."""
    if depth.dim() != 4 or depth.shape[1] != 1 or not depth.is_floating_point():
        raise TypeError(f"depth must be a float [B, 1, H, W] tensor in metres, got {depth.dtype} {list(depth.shape)}")
    x = depth.float()
    if x.shape[-2:] != (size, size):
        x = F.interpolate(x, size=(size, size), mode="bilinear", align_corners=False, antialias=True)
    return x


def standardise_depth(depth: torch.Tensor, size: int) -> torch.Tensor:
    """float depth [B, 1, H, W] (metres) → float [B, 1, size, size] standardised (``resize_depth``, then the
    camera's mean and spread)."""
    return (resize_depth(depth, size) - DEPTH_MEAN) / DEPTH_STD


def input_size(image_size: int, detail: int, backbone: str = "unet") -> int:
    """The side of the standardised image a perception takes: the full render (2 × ``image_size``) with the
    detail path or the ImageNet backbone (whose finest map is at stride 4), else ``image_size``."""
    return int(image_size) * (2 if detail or backbone != "unet" else 1)


def check_backbone(backbone: str, detail: int = 0, imagenet: bool = False, depth: bool = False) -> None:
    """ValueError unless ``backbone`` is known, reads the full render without the detail path, (``imagenet``)
    has ImageNet weights and (``depth``) takes a depth channel; the recipe calls it before loading frames,
    the model when built."""
    if backbone not in BACKBONES:
        raise ValueError(f"unknown backbone {backbone!r}; known: {list(BACKBONES)}")
    if depth and backbone != "unet":
        raise ValueError(f"depth=true: the depth channel exists for backbone=unet only (got {backbone}, whose "
                         f"ImageNet stem reads 3 channels)")
    if detail and backbone != "unet":
        raise ValueError(f"backbone={backbone} reads the full render already: set detail=0 (got {detail})")
    if imagenet and backbone == "unet":
        raise ValueError("imagenet=true: ImageNet weights exist for model.backbone=efficientnet_lite0 only "
                         "(this perception is a unet)")


def _block(cin: int, cout: int, stride: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride=stride, padding=1, bias=False), nn.BatchNorm2d(cout),
                         nn.ReLU(inplace=True),
                         nn.Conv2d(cout, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class CountingPerception(nn.Module):
    """Standardised rgb [B, 3, S, S] → (class logits [B, K, S/2, S/2], votes [B, 2, S/2, S/2],
    density [B, 1, S/2, S/2] ≥ 0).

    ``widths``: channels at strides 2, 4, 8, 16 (the deepest sees ~100 px of the 112-px input: the
    whole of the largest object). ``detail``: channels of the full-resolution path (0: none; with it the
    input is 2 × ``image_size``). ``backbone="efficientnet_lite0"``: the encoder is EfficientNet-Lite0's
    (``push.imagenet_backbone``; ``load_imagenet`` gives it ImageNet weights) reading the full render, and
    ``widths`` are the decoder's (the fourth unused). ``depth``: a fourth input channel, the standardised depth
    image (``predict`` then needs it). Votes are in output cells, relative to the cell's centre."""

    def __init__(self, num_classes: int, widths=(32, 48, 96, 128), image_size: int = 112, counting: dict | None = None,
                 detail: int = 0, backbone: str = "unet", depth: bool = False):
        super().__init__()
        unknown = set(counting or {}) - set(vote_counting.DEFAULT_COUNTING)
        if unknown:
            raise ValueError(f"unknown counting settings {sorted(unknown)}; known: {sorted(vote_counting.DEFAULT_COUNTING)}")
        self.counting = {**vote_counting.DEFAULT_COUNTING, **(counting or {})}
        if len(widths) != 4:
            raise ValueError(f"widths must name 4 stages (strides 2, 4, 8, 16), got {list(widths)}")
        if image_size % 16:
            raise ValueError(f"image_size must be a multiple of 16, got {image_size}")
        if detail < 0:
            raise ValueError(f"detail must be ≥ 0 channels (0: no full-resolution path), got {detail}")
        check_backbone(backbone, detail, depth=depth)
        self.depth = bool(depth)
        cin = 4 if self.depth else 3
        self.num_classes = int(num_classes)
        self.widths = tuple(int(w) for w in widths)
        self.image_size = int(image_size)
        self.backbone = backbone
        w1, w2, w3, w4 = self.widths
        if backbone == "unet":
            self.down = nn.ModuleList([_block(cin, w1, 2), _block(w1, w2, 2), _block(w2, w3, 2), _block(w3, w4, 2)])
            c1, c2, c3, c4 = self.widths
        else:
            self.encoder = EfficientLiteEncoder()
            c1, c2, c3, c4 = EfficientLiteEncoder.channels
        self.detail_width = int(detail)
        if detail:
            self.detail = nn.Sequential(_block(cin, detail, 2), _block(detail, w1, 2), nn.Conv2d(w1, w1, 1))
            nn.init.zeros_(self.detail[-1].weight)
            nn.init.zeros_(self.detail[-1].bias)
        self.up3 = _block(c4 + c3, w3, 1)
        self.up2 = _block(w3 + c2, w2, 1)
        self.up1 = _block(w2 + c1, w1, 1)
        self.classes = nn.Conv2d(w1, self.num_classes, 1)
        self.votes = nn.Conv2d(w1, 2, 1)
        self.density = nn.Conv2d(w1, 1, 1)
        nn.init.constant_(self.density.bias, DENSITY_BIAS)

    @property
    def out_size(self) -> int:
        return self.image_size // 2

    @property
    def input_size(self) -> int:
        return input_size(self.image_size, self.detail_width, self.backbone)

    @property
    def cell_px(self) -> float:
        """Pixels of the 224-px render one output cell covers (16 at 112 px in, 56 out)."""
        return (RENDER_SIZE / self.out_size) ** 2

    def load_imagenet(self) -> None:
        """Start the EfficientNet-Lite0 encoder from ImageNet (the ablation's other arm starts from scratch)."""
        check_backbone(self.backbone, imagenet=True)
        self.encoder.load_imagenet()

    def encode(self, x: torch.Tensor) -> list[torch.Tensor]:
        """Standardised rgb (and depth: ``inputs``) → the encoder's four maps, finest (the output's cells) first."""
        if self.backbone != "unet":
            return self.encoder(x)
        if self.detail_width:          # the main path reads the render at image_size, the detail path in full
            small = F.interpolate(x, size=(self.image_size, self.image_size), mode="bilinear", align_corners=False,
                                  antialias=True)
            x = self.down[0](small) + self.detail(x)
        else:
            x = self.down[0](x)
        skips = [x]
        for stage in self.down[1:]:
            x = stage(x)
            skips.append(x)
        return skips

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        s1, s2, s3, x = self.encode(x)
        for up, skip in ((self.up3, s3), (self.up2, s2), (self.up1, s1)):
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = up(torch.cat([x, skip], 1))
        return self.classes(x), self.votes(x), F.softplus(self.density(x))

    def inputs(self, rgb: torch.Tensor, depth: torch.Tensor | None = None, crop: bool = False) -> torch.Tensor:
        """uint8 rgb [B, 3, H, W] (and, for a perception with ``depth``, float depth [B, 1, H, W] in metres) →
        the network's standardised input; ``crop``: the images are crops of frames at ``input_size``, taken as
        they are (training on crops), not resized to a whole frame."""
        size = rgb.shape[-1] if crop else self.input_size
        x = standardise(rgb, size)
        if not self.depth:
            return x
        if depth is None:
            raise ValueError("this perception reads depth too (trained with model.depth=true): pass the frame's depth "
                             "image (metres, [B, 1, H, W]) beside its rgb")
        return torch.cat([x, standardise_depth(depth.to(x.device), size)], 1)

    def predict(self, rgb: torch.Tensor, depth: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """uint8 rgb [B, 3, H, W] (and depth, see ``inputs``) → (class probabilities [B, K, s, s], votes
        [B, 2, s, s], density [B, 1, s, s])."""
        logits, votes, density = self(self.inputs(rgb, depth))
        return logits.softmax(1), votes, density

    def count_features(self, rgb: torch.Tensor, trainable: bool = False, depth: torch.Tensor | None = None) -> torch.Tensor:
        """uint8 rgb [B, 3, H, W] (and depth) → the VQA's per-class count features [B, K, F] (``vote_counting``),
        with this perception's own counting settings; ``trainable``: with gradients (fine-tuning under the VQA)."""
        with torch.set_grad_enabled(trainable and torch.is_grad_enabled()):
            probs, votes, density = (t.float().cpu() for t in self.predict(rgb, depth))
            read = vote_counting.trainable_count_features if trainable else vote_counting.count_features
            return read(probs, votes, density, self.cell_px, **self.counting)

    def counts(self, rgb: torch.Tensor, depth: torch.Tensor | None = None) -> torch.Tensor:
        """uint8 rgb [B, 3, H, W] (and depth) → int64 [B, K-1]: the objects of each class (1 … K-1) it counts."""
        probs, votes, density = (t.float().cpu() for t in self.predict(rgb, depth))
        return vote_counting.counts(probs, votes, density, self.cell_px, **self.counting)

    def config(self) -> dict:
        return {"num_classes": self.num_classes, "widths": list(self.widths), "image_size": self.image_size,
                "counting": dict(self.counting), "detail": self.detail_width, "backbone": self.backbone,
                "depth": self.depth}


def save_perception(model: CountingPerception, path: str | Path, meta: dict) -> Path:
    """Write the weights, architecture and ``meta`` (training data, command, scores) atomically."""
    return save_versioned(path, PERCEPTION_FORMAT, PERCEPTION_VERSION,
                          {"config": model.config(), "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
                           "meta": dict(meta)})


def check_library(perception: CountingPerception, dataset_classes: int, path) -> None:
    """ValueError when a perception was trained on another object library (its class channels are not background
    plus the dataset's classes): read anyway it would index past its channels after minutes of episodes."""
    if perception.num_classes != 1 + int(dataset_classes):
        raise ValueError(f"perception {path} knows {perception.num_classes - 1} classes, the dataset {dataset_classes}: "
                         f"train one on frames of this object library (recipes/train_perception.py)")


def load_perception(path: str | Path) -> tuple[CountingPerception, dict]:
    """(perception in eval mode, meta) from ``save_perception``'s file; FileNotFoundError / ValueError say what to do."""
    hint = "train one with `python recipes/train_perception.py` (it writes <out_dir>/perception.pt)"
    blob = load_versioned(path, PERCEPTION_FORMAT, PERCEPTION_VERSION, what="perception file", hint=hint)
    check_sane(blob.get("config"), blob.get("state_dict"), path, hint)
    try:
        model = CountingPerception(**blob["config"])
        model.load_state_dict(blob["state_dict"])
    except (KeyError, TypeError, RuntimeError, ValueError) as error:
        raise ValueError(f"{path}: the weights do not fit the perception ({type(error).__name__}: {str(error)[:300]}); "
                         f"{hint}") from error
    return model.eval(), dict(blob.get("meta", {}))


# the convolutions that read the input image (a depth perception's read a fourth channel)
STEMS = ("down.0.0.weight", "detail.0.0.weight")


def init_from_file(model: CountingPerception, path: str) -> None:
    """Start from a perception file's weights (same architecture); heads it lacks keep their initialisation,
    and a depth perception started from an rgb file gets its stems' rgb weights with the depth channel's at zero
    (so it starts exactly where the rgb file stands)."""
    blob = load_versioned(path, PERCEPTION_FORMAT, PERCEPTION_VERSION, what="perception file (init_from)",
                          hint="name a perception.pt of recipes/train_perception.py")
    state = dict(blob["state_dict"])
    own = model.state_dict()
    for name in STEMS:
        if name in state and name in own and state[name].shape[1] == 3 and own[name].shape[1] == 4:
            state[name] = torch.cat([state[name], torch.zeros_like(state[name][:, :1])], 1)
    try:
        missing, unexpected = model.load_state_dict(state, strict=False)
        shapes = ""
    except RuntimeError as error:              # a tensor of another shape (widths, a depth file into an rgb net)
        missing, unexpected, shapes = [], [], f"; {str(error).strip().splitlines()[-1].strip()}"
    if shapes or unexpected or any(not k.startswith(("density.", "detail.")) for k in missing):
        raise ValueError(f"init_from={path} does not fit model.widths={list(model.widths)}, model.detail={model.detail_width}, "
                         f"model.backbone={model.backbone}, model.depth={model.depth} "
                         f"(missing {missing[:4]}, unexpected {unexpected[:4]}{shapes}): match the architecture it was trained with")
    print(f"started from {path} (new heads: {sorted({k.split('.')[0] for k in missing}) or 'none'})")


# what a perception file's architecture may ask for before anything is allocated (a crafted width would take GBs)
LIMITS = {"num_classes": 1024, "image_size": 2048, "detail": 512, "width": 4096}


def check_sane(config, state_dict, path, hint: str) -> None:
    """ValueError for a perception file whose architecture is out of bounds, whose counting settings are not finite
    numbers, or whose weights hold NaN or infinity: such a file would load and count 0 silently, or allocate GBs."""
    if not isinstance(config, dict) or not isinstance(state_dict, dict):
        raise ValueError(f"{path}: no architecture or weights in the perception file; {hint}")
    sizes = {k: config.get(k, 0) for k in ("num_classes", "image_size", "detail")}
    sizes.update({f"widths[{i}]": w for i, w in enumerate(config.get("widths") or ())})
    for name, value in sizes.items():
        limit = LIMITS.get(name, LIMITS["width"])
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= limit:
            raise ValueError(f"{path}: {name}={value!r} is not a size a perception has (0-{limit}); {hint}")
    for name, value in (config.get("counting") or {}).items():
        if isinstance(value, (int, float)) and not isinstance(value, bool) and not math.isfinite(value):
            raise ValueError(f"{path}: the counting setting {name}={value} is not a finite number; {hint}")
    refuse_nonfinite(state_dict, path, hint)

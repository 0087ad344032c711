"""A push head shared by the eight directions: rotate the state, score "push to the right", rotate back.

The paper's head gives each direction its own output channel, so what it learns about pushing right
teaches it nothing about pushing up, and each demonstration or reward trains one direction in eight.
VPG (Zeng et al. 2018, the paper's anchor for push Q-maps) instead rotates the input so that every push
points the same way and applies one network. Here the rotation acts on the 28×28 state (after a 1×1
reduction, so it is cheap): for direction d the map is rotated by −45°·d (bilinear), padded so that the
bin's corners survive, through 3×3 context convs and 1×1 convs to one map, and rotated back. The stop
map comes from the same layers with their own weights on the unrotated state.

``push_channels``: the push branch reads its own input (``forward(state, push_input)``), e.g. only the
question's target map and the height map (``PushQNet(geometric_push=True)``), while the stop branch keeps
the whole state.

Rotation equivariance by construction: rotating the scene by 90° moves Q of direction d to direction
d + 2, rotated (``tests/integration/test_push_qnet.py``). Directions follow ``mqa_rl.envs.actions``: d·45°
counter-clockwise as seen in the image (d = 0 points right, d = 2 up).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from mqa_rl.modules.push.trunks import conv_stack


def _branch(width: int, context: int, head_channels: tuple[int, ...]) -> nn.Sequential:
    """3×3 context convs at ``width``, then 1×1 convs down to one map."""
    return nn.Sequential(conv_stack([width] * (context + 1), kernel=3),
                         conv_stack([width, *head_channels[1:], 1], last_relu=False))


class RotatedPushHead(nn.Module):
    """state [B, C, G, G] → [B, directions + 1, G, G]: push maps by direction, then the stop map."""

    def __init__(self, state_channels: int, head_channels: tuple[int, ...] = (16, 16), context: int = 2,
                 directions: int = 8, pad: int = 2, push_channels: int | None = None):
        super().__init__()
        width = head_channels[0]
        self.reduce = nn.Sequential(nn.Conv2d(state_channels, width, 1), nn.ReLU(inplace=True))
        self.push_reduce = (nn.Sequential(nn.Conv2d(push_channels, width, 1), nn.ReLU(inplace=True))
                            if push_channels else None)
        self.push = _branch(width, context, tuple(head_channels))
        self.stop = _branch(width, context, tuple(head_channels))
        self.directions, self.pad = int(directions), int(pad)
        angles = torch.tensor([2 * math.pi * d / directions for d in range(directions)])
        c, s = torch.cos(angles), torch.sin(angles)
        zero = torch.zeros_like(c)
        # affine_grid samples the input at A·(x_out, y_out) (x right, y down): A_d turns +x_out into the
        # image direction of push d, (cos θ, −sin θ); its transpose turns the result back.
        self.register_buffer("to_push_frame", torch.stack([torch.stack([c, s, zero], -1),
                                                           torch.stack([-s, c, zero], -1)], 1), persistent=False)
        self.register_buffer("to_image_frame", torch.stack([torch.stack([c, -s, zero], -1),
                                                            torch.stack([s, c, zero], -1)], 1), persistent=False)

    def _rotate(self, x: torch.Tensor, theta: torch.Tensor) -> torch.Tensor:
        grid = F.affine_grid(theta.to(x.dtype), list(x.shape), align_corners=False)
        return F.grid_sample(x, grid, mode="bilinear", padding_mode="zeros", align_corners=False)

    def forward(self, state: torch.Tensor, push_input: torch.Tensor | None = None) -> torch.Tensor:
        k, p = self.directions, self.pad
        shared = self.reduce(state)
        stop = self.stop(shared)
        if self.push_reduce is not None and push_input is None:
            raise ValueError("this head's push branch reads its own input: pass push_input to the head")
        x = self.push_reduce(push_input) if self.push_reduce is not None else shared
        b, _, g, _ = x.shape
        x = F.pad(x, (p, p, p, p))
        x = x.unsqueeze(1).expand(-1, k, -1, -1, -1).reshape(b * k, *x.shape[1:])
        push = self.push(self._rotate(x, self.to_push_frame.repeat(b, 1, 1)))
        push = self._rotate(push, self.to_image_frame.repeat(b, 1, 1))[..., p:p + g, p:p + g]
        return torch.cat([push.reshape(b, k, g, g), stop], 1)

"""The bin's symmetries as replay augmentation: each sampled transition seen rotated or mirrored.

The bin is square and the camera looks straight down at its centre, so turning the whole picture
by 90° (or mirroring it) gives another scene the robot could meet, whose pushes are the same pushes
turned alike and earn the same reward (the physics has no preferred horizontal direction). The 8
elements of the square's symmetry group (dihedral group D4) turn one stored transition into 8
training examples: a pixel-wise Q-network must otherwise learn "push the occluder away from the
target" separately for every direction and every part of the bin, from a few thousand frames.

Image rotation by k·90° counter-clockwise (``torch.rot90``, as seen) maps push direction d → d + 2k
(directions turn counter-clockwise in the image, ``mqa_rl.envs.actions``) and cell (r, c) → (N−1−c, r)
per quarter turn; the mirror (columns reversed) maps d → 4 − d and (r, c) → (r, N−1−c). Stop stays stop.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.envs import Transform

from mqa_rl import keys
from mqa_rl.envs import actions

IMAGE_KEYS = (keys.RGB, keys.DEPTH)


def transform_push_map(q: torch.Tensor, k: int, mirror: bool) -> torch.Tensor:
    """Apply the symmetry to per-action values [..., 6273] (a Q vector, a mask)."""
    push = q[..., : actions.NUM_PUSHES].unflatten(-1, (actions.DIRECTIONS, actions.GRID, actions.GRID))
    if mirror:
        push = push.flip(-1)[..., (4 - torch.arange(actions.DIRECTIONS)) % actions.DIRECTIONS, :, :]
    if k:
        push = torch.rot90(push, k, dims=(-2, -1))
        push = push[..., (torch.arange(actions.DIRECTIONS) - 2 * k) % actions.DIRECTIONS, :, :]
    return torch.cat([push.flatten(-3), q[..., actions.NUM_PUSHES:]], -1)


def transform_action(action: torch.Tensor, k: int, mirror: bool) -> torch.Tensor:
    """The index of the same push after the symmetry (stop unchanged); ``action`` int64 [...]."""
    stop = action == actions.STOP
    a = action.clamp(max=actions.NUM_PUSHES - 1)
    d, rest = a // (actions.GRID * actions.GRID), a % (actions.GRID * actions.GRID)
    r, c = rest // actions.GRID, rest % actions.GRID
    n = actions.GRID - 1
    if mirror:
        d, c = (4 - d) % actions.DIRECTIONS, n - c
    for _ in range(k):
        d, r, c = (d + 2) % actions.DIRECTIONS, n - c, r
    return torch.where(stop, action, d * actions.GRID * actions.GRID + r * actions.GRID + c)


def transform_images(x: torch.Tensor, k: int, mirror: bool) -> torch.Tensor:
    if mirror:
        x = x.flip(-1)
    return torch.rot90(x, k, dims=(-2, -1)) if k else x


class DihedralAugment(Transform):
    """Replay-buffer transform: every sampled transition under a random symmetry of the square.

    Both observations (``root`` and ``"next"``), their action masks, the action and the visible-target
    cells (if stored) are turned alike;
    reward, done flags, question and the sample's buffer ``index`` (for priority updates) stay.
    """

    def __init__(self, generator: torch.Generator | None = None):
        super().__init__(in_keys=[], out_keys=[])
        self.generator = generator

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        flat = tensordict.reshape(-1)
        picks = torch.randint(0, 8, (flat.shape[0],), generator=self.generator)
        for g in picks.unique().tolist():
            k, mirror = g % 4, g >= 4
            if g == 0:
                continue
            idx = (picks == g).nonzero().squeeze(-1)
            for prefix in ((), ("next",)):
                if prefix and "next" not in flat.keys():         # demonstrations: states without successors
                    continue
                for key in IMAGE_KEYS:
                    name = (*prefix, key)
                    flat.get(name)[idx] = transform_images(flat.get(name)[idx], k, mirror)
                mask = (*prefix, keys.ACTION_MASK)
                flat.get(mask)[idx] = transform_push_map(flat.get(mask)[idx], k, mirror)
            flat.get(keys.ACTION)[idx] = transform_action(flat.get(keys.ACTION)[idx], k, mirror)
            if keys.TARGET_CELLS in flat.keys(True):                 # a grid map: turns like the images
                flat.get(keys.TARGET_CELLS)[idx] = transform_images(flat.get(keys.TARGET_CELLS)[idx], k, mirror)
        return flat.reshape(tensordict.shape)

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:   # not an env transform
        return next_tensordict

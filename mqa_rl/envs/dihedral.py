"""The bin's symmetries: the 8 rotations and mirrors of the square (dihedral group D4) on images, on
push maps and actions, and as replay augmentation (``DihedralAugment``).

The bin is square and the camera looks straight down at its centre, so turning the whole picture
by 90° (or mirroring it) gives another scene the robot could meet, whose pushes are the same pushes
turned alike and earn the same reward (the physics has no preferred horizontal direction). The 8
elements of the square's symmetry group turn one stored transition into 8 training examples: a
pixel-wise Q-network must otherwise learn "push the occluder away from the target" separately for
every direction and every part of the bin, from a few thousand frames. The same holds for the
answers of a question (counting, existence, logic and "under" are all invariant), hence the frame
pipelines' augmentation.

A symmetry is ``(k, mirror)``: mirror first (columns reversed), then k quarter turns counter-clockwise
(``torch.rot90``, as seen). Image rotation by k·90° maps push direction d → d + 2k (directions turn
counter-clockwise in the image, ``mqa_rl.envs.actions``) and cell (r, c) → (N−1−c, r) per quarter
turn; the mirror maps d → 4 − d and (r, c) → (r, N−1−c). Stop stays stop.

Two numberings of the 8 by an index i ∈ [0, 8) are in use, each in the training of shipped models (kept
so that a seeded run draws the same symmetries as before):
* mirror first, ``mirror_first(i)`` = (i % 4, i ≥ 4): ``DihedralAugment``, the DQN's replay and
  demonstrations;
* turns first, ``dihedral(x, i)``: the image turned i % 4 quarter turns, then mirrored when i ≥ 4 (the
  VQA's feature cache and batches, the pretraining of the VQA encoder, the perception and the push trunk).
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.envs import Transform

from mqa_rl import keys
from mqa_rl.envs import actions

# what turns like the images: the frames and, where stored, a grid map (the visible-target cells)
TURNED_MAPS = (keys.RGB, keys.DEPTH, keys.TARGET_CELLS)
DIHEDRAL = 8            # the number of symmetries


def mirror_first(index: int) -> tuple[int, bool]:
    """``(k, mirror)`` of symmetry ``index`` ∈ [0, 8) in the replay's numbering: k = index % 4, mirrored when ≥ 4."""
    return index % 4, index >= 4


def dihedral(x: torch.Tensor, index: int) -> torch.Tensor:
    """Symmetry ``index`` ∈ [0, 8) of an image's last two dims in the frame pipelines' numbering: index % 4
    quarter turns, then mirrored when index ≥ 4; that is ``transform_images(x, -index % 4, True)`` for
    index ≥ 4 (mirroring after the turns is mirroring before turns the other way)."""
    x = torch.rot90(x, index % 4, dims=(-2, -1))
    return x.flip(-1) if index >= 4 else x


def random_dihedral(*images: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """The same random symmetry per frame of each of ``images`` ([B, ..., S, S]: rgb, depth, label maps), for the
    frame pipelines that learn from single frames: the bin seen from above is symmetric. Drawn on the CPU, so that a
    seed gives the same stream on any device."""
    k = torch.randint(DIHEDRAL, (images[0].shape[0],)).to(images[0].device)
    out = tuple(x.clone() for x in images)
    for t in k.unique().tolist():
        for x, y in zip(images, out):
            y[k == t] = dihedral(x[k == t], t)
    return out


def random_dihedral_in(batch: TensorDictBase, names) -> TensorDictBase:
    """``random_dihedral`` of the entries ``names`` of a frame batch, written back in place."""
    for key, x in zip(names, random_dihedral(*(batch.get(key) for key in names))):
        batch.set(key, x)
    return batch


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
    """Replay-buffer transform: every sampled transition under a random symmetry of the square
    (``mirror_first`` numbering).

    Both observations (``root`` and ``"next"``, their perceived classes if stored), their action masks, the action and
    the visible-target cells (if stored) are turned alike;
    reward, done flags, question and the sample's buffer ``index`` (for priority updates) stay.
    """

    def __init__(self, generator: torch.Generator | None = None):
        super().__init__(in_keys=[], out_keys=[])
        self.generator = generator

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        flat = tensordict.reshape(-1)
        picks = torch.randint(0, DIHEDRAL, (flat.shape[0],), generator=self.generator)
        for g in picks.unique().tolist():
            k, mirror = mirror_first(g)
            if g == 0:
                continue
            idx = (picks == g).nonzero().squeeze(-1)
            for prefix in ((), ("next",)):
                if prefix and "next" not in flat.keys():         # demonstrations: states without successors
                    continue
                for key in TURNED_MAPS:
                    name = (*prefix, key)
                    if flat.get(name, None) is not None:
                        flat.get(name)[idx] = transform_images(flat.get(name)[idx], k, mirror)
                mask = (*prefix, keys.ACTION_MASK)
                flat.get(mask)[idx] = transform_push_map(flat.get(mask)[idx], k, mirror)
            flat.get(keys.ACTION)[idx] = transform_action(flat.get(keys.ACTION)[idx], k, mirror)
        return flat.reshape(tensordict.shape)

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:   # not an env transform
        return next_tensordict

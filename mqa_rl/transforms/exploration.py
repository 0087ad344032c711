"""R_e, the exploration reward: how far the push moved the object that moved most."""

from __future__ import annotations

import torch

from mqa_rl import keys
from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.checks import finite_number, required
from mqa_rl.transforms.functional import EXPLORATION_CAP, exploration_reward

SCALES = ("push_length", "position_norm")


class ExplorationReward(RewardTerm):
    """R_e = max_i |p_i − p_i'| / s_i.

    ``scale="push_length"`` (default) divides by the push length in the world, as the authors' code
    did: R_e ≈ 1 when an object travels with the finger, independent of where the world origin is.
    ``scale="position_norm"`` is the paper's printed s_i = |p_i|, which depends on the origin (here
    the bin centre, so objects near the centre earn huge ratios; kept for reproduction studies).
    Ratios ≥ ``cap`` are treated as non-physical jumps and ignored (``cap=None`` keeps all).
    Positions of real objects (``object_mask``) must be finite; padding slots are ignored.
    """

    out_key = keys.EXPLORATION

    def __init__(self, push_length: float, scale: str = "push_length", cap: float | None = EXPLORATION_CAP):
        super().__init__()
        if scale not in SCALES:
            raise ValueError(f"unknown exploration scale {scale!r}; allowed: {SCALES}")
        self.push_length = finite_number(self, "push_length", push_length, positive=True)
        self.scale = scale
        self.cap = None if cap is None else finite_number(self, "cap (None keeps every ratio)", cap, positive=True)

    def compute(self, before, after) -> torch.Tensor:
        mask = required(self, before, keys.OBJECT_MASK, "root")
        p0 = self.measured(before, keys.OBJECT_POS, "root", mask)
        p1 = self.measured(after, keys.OBJECT_POS, "next", mask)
        s = self.push_length if self.scale == "push_length" else p0.norm(dim=-1)
        return exploration_reward(p0, p1, mask, s, self.cap)

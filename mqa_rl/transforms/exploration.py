"""R_e, the exploration reward: how far the push moved the object that moved most."""

from __future__ import annotations

import torch

from mqa_rl import keys
from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.functional import EXPLORATION_CAP, exploration_reward

SCALES = ("push_length", "position_norm")


class ExplorationReward(RewardTerm):
    """R_e = max_i |p_i − p_i'| / s_i.

    ``scale="push_length"`` (default) divides by the push length in the world, as the authors' code
    did: R_e ≈ 1 when an object travels with the finger, independent of where the world origin is.
    ``scale="position_norm"`` is the paper's printed s_i = |p_i|, which depends on the origin (here
    the bin centre, so objects near the centre earn huge ratios; kept for reproduction studies).
    Ratios ≥ ``cap`` are treated as non-physical jumps and ignored (``cap=None`` keeps all).
    """

    out_key = keys.EXPLORATION

    def __init__(self, push_length: float, scale: str = "push_length", cap: float | None = EXPLORATION_CAP):
        super().__init__()
        if scale not in SCALES:
            raise ValueError(f"unknown exploration scale {scale!r}; allowed: {SCALES}")
        if push_length <= 0:
            raise ValueError(f"push_length must be positive, got {push_length}")
        self.push_length = float(push_length)
        self.scale = scale
        self.cap = cap

    def compute(self, before, after) -> torch.Tensor:
        p0, p1 = before.get(keys.OBJECT_POS), after.get(keys.OBJECT_POS)
        s = self.push_length if self.scale == "push_length" else p0.norm(dim=-1)
        return exploration_reward(p0, p1, before.get(keys.OBJECT_MASK), s, self.cap)

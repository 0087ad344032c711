"""R_c: the push's net gain in targets a perfect counter can count (ours, not the paper's).

R_g and R_l score how much of the targets shows (χ), but an answer counts a target once enough of it
shows: a push that uncovers a target already counted, or uncovers one while burying another, leaves the
answer where it was. R_c scores the crossings of the perfect counter's line instead: the targets that rose to
≥ ``min_px`` visible pixels minus those that fell below it, over the number of targets (``normalise:
targets``) or as a count (``normalise: none``). It reads the visible areas before and after the action on
the targets (``target_mask`` before it); areas must be finite on the targets, other slots are ignored.
"""

from __future__ import annotations

import torch

from mqa_rl import keys
from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.checks import finite_number, required
from mqa_rl.transforms.episode_stats import COUNTABLE_PX
from mqa_rl.transforms.functional import countable_targets_reward

NORMALISATIONS = ("targets", "none")


class CountableTargetsReward(RewardTerm):
    """R_c = (targets made countable − targets buried) / targets, the counting line at ``min_px`` visible pixels."""

    out_key = keys.COUNTABLE_TARGETS

    def __init__(self, min_px: float = COUNTABLE_PX, normalise: str = "targets"):
        super().__init__()
        self.min_px = finite_number(self, "min_px", min_px, positive=True)
        if normalise not in NORMALISATIONS:
            raise ValueError(f"CountableTargetsReward: normalise must be one of {list(NORMALISATIONS)} (over the "
                             f"question's targets, or the raw count), got {normalise!r}")
        self.normalise = normalise

    def compute(self, before, after) -> torch.Tensor:
        targets = required(self, before, keys.TARGET_MASK, "root")
        visible0 = self.measured(before, keys.VISIBLE_AREA, "root", targets)
        visible1 = self.measured(after, keys.VISIBLE_AREA, "next", targets)
        return countable_targets_reward(visible0, visible1, targets, self.min_px, self.normalise == "targets")

"""R_g and R_l: how much a push uncovered the question's target objects; R_s: the whole scene.

Both read the overlap χ before and after the action on the targets (``target_mask`` before it): χ
of a target must be finite; non-target and padding slots are ignored, whatever they hold.
"""

from __future__ import annotations

import torch

from mqa_rl import keys
from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.checks import required
from mqa_rl.transforms.functional import global_occlusion_reward, local_occlusion_reward


def _target_overlaps(term: RewardTerm, before, after) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """χ before, χ after and the target mask (before the action), χ checked finite on the targets."""
    targets = required(term, before, keys.TARGET_MASK, "root")
    return term.measured(before, keys.OVERLAP, "root", targets), term.measured(after, keys.OVERLAP, "next", targets), targets


class GlobalOcclusionReward(RewardTerm):
    """R_g = (χ_a − χ_a') / χ_a, χ_a the mean overlap of the targets (the whole target class)."""

    out_key = keys.GLOBAL_OCCLUSION

    def compute(self, before, after) -> torch.Tensor:
        return global_occlusion_reward(*_target_overlaps(self, before, after))


class LocalOcclusionReward(RewardTerm):
    """R_l = (max χ − max χ') / max χ over the targets: progress on the most hidden one.

    ``reduce`` is "max" (paper) or "min" (progress on the least hidden target).
    """

    out_key = keys.LOCAL_OCCLUSION

    def __init__(self, reduce: str = "max"):
        super().__init__()
        if reduce not in ("max", "min"):
            raise ValueError(f"LocalOcclusionReward: reduce must be 'max' or 'min', got {reduce!r}")
        self.reduce = reduce

    def compute(self, before, after) -> torch.Tensor:
        return local_occlusion_reward(*_target_overlaps(self, before, after), self.reduce)


class SceneOcclusionReward(RewardTerm):
    """R_s = (χ_a − χ_a') / χ_a over EVERY object: how much the push uncluttered the scene.

    Not in the paper. It can stand in for R_e as the β-weighted, question-agnostic term
    (``explore_term: scene_occlusion`` in a reward config): R_e pays for moving objects, which on a
    pile also pays for shoving them onto it, while R_s pays for uncovering, whatever is asked; and
    it averages over all the scene's objects, so it is far less noisy than R_g over 1-3 targets.
    """

    out_key = keys.SCENE_OCCLUSION

    def compute(self, before, after) -> torch.Tensor:
        objects = required(self, before, keys.OBJECT_MASK, "root")
        chi0 = self.measured(before, keys.OVERLAP, "root", objects)
        chi1 = self.measured(after, keys.OVERLAP, "next", objects)
        return global_occlusion_reward(chi0, chi1, objects)

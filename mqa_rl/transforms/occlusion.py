"""R_g and R_l: how much a push uncovered the question's target objects; R_s: the whole scene.

Both read the overlap χ before and after the action on the targets (``target_mask`` before it): χ
of a target must be finite; non-target and padding slots are ignored, whatever they hold.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from mqa_rl import keys
from mqa_rl.data.questions import QUESTION_TYPES
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

    ``reduce`` is "max" (paper), "min", or a mapping from question type to either, e.g.
    ``{"existence": "min"}`` (the authors' code: one uncovered instance answers EXISTENCE);
    types not in the mapping use "max".
    """

    out_key = keys.LOCAL_OCCLUSION

    def __init__(self, reduce: str | dict[str, str] = "max"):
        super().__init__()
        per_type = {t: "max" for t in QUESTION_TYPES}
        if not isinstance(reduce, (str, Mapping)):
            raise ValueError(f"LocalOcclusionReward: reduce is 'max', 'min' or {{question type: 'max' | 'min'}}, got {reduce!r}")
        if isinstance(reduce, str):
            per_type = {t: reduce for t in QUESTION_TYPES}
        else:
            unknown = set(reduce) - set(QUESTION_TYPES)
            if unknown:
                raise ValueError(f"LocalOcclusionReward: unknown question types {sorted(unknown, key=str)} in reduce; "
                                 f"allowed: {QUESTION_TYPES}")
            per_type.update(reduce)
        bad = set(per_type.values()) - {"max", "min"}
        if bad:
            raise ValueError(f"LocalOcclusionReward: reduce must be 'max' or 'min', got {sorted(bad, key=str)}")
        self.reduce = per_type
        self.register_buffer("_use_min", torch.tensor([per_type[t] == "min" for t in QUESTION_TYPES]), persistent=False)

    def compute(self, before, after) -> torch.Tensor:
        chi0, chi1, tgt = _target_overlaps(self, before, after)
        r_max = local_occlusion_reward(chi0, chi1, tgt, "max")
        if not self._use_min.any():
            return r_max
        r_min = local_occlusion_reward(chi0, chi1, tgt, "min")
        qtype = required(self, before, keys.QUESTION_TYPE, "root").squeeze(-1)
        if ((qtype < 0) | (qtype >= len(QUESTION_TYPES))).any():
            raise ValueError(f"LocalOcclusionReward: {keys.QUESTION_TYPE!r} must index QUESTION_TYPES "
                             f"[0, {len(QUESTION_TYPES)}), got {qtype.tolist()}")
        return torch.where(self._use_min.to(qtype.device)[qtype], r_min, r_max)


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

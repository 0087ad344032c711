"""R_g and R_l: how much a push uncovered the question's target objects."""

from __future__ import annotations

import torch

from mqa_rl import keys
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.functional import global_occlusion_reward, local_occlusion_reward


class GlobalOcclusionReward(RewardTerm):
    """R_g = (χ_a − χ_a') / χ_a, χ_a the mean overlap of the targets (the whole target class)."""

    out_key = keys.GLOBAL_OCCLUSION

    def compute(self, before, after) -> torch.Tensor:
        return global_occlusion_reward(before.get(keys.OVERLAP), after.get(keys.OVERLAP), before.get(keys.TARGET_MASK))


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
        if isinstance(reduce, str):
            per_type = {t: reduce for t in QUESTION_TYPES}
        else:
            unknown = set(reduce) - set(QUESTION_TYPES)
            if unknown:
                raise ValueError(f"unknown question types {sorted(unknown)}; allowed: {QUESTION_TYPES}")
            per_type.update(reduce)
        bad = set(per_type.values()) - {"max", "min"}
        if bad:
            raise ValueError(f"reduce must be 'max' or 'min', got {sorted(bad)}")
        self.reduce = per_type
        self.register_buffer("_use_min", torch.tensor([per_type[t] == "min" for t in QUESTION_TYPES]), persistent=False)

    def compute(self, before, after) -> torch.Tensor:
        chi0, chi1, tgt = before.get(keys.OVERLAP), after.get(keys.OVERLAP), before.get(keys.TARGET_MASK)
        r_max = local_occlusion_reward(chi0, chi1, tgt, "max")
        if not self._use_min.any():
            return r_max
        r_min = local_occlusion_reward(chi0, chi1, tgt, "min")
        qtype = before.get(keys.QUESTION_TYPE).squeeze(-1)
        return torch.where(self._use_min.to(qtype.device)[qtype], r_min, r_max)

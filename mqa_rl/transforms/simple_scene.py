"""The simple-scene flag: the scene *before* the action already answers the question."""

from __future__ import annotations

import torch

from mqa_rl import keys
from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.checks import finite_number, required
from mqa_rl.transforms.functional import is_simple_scene


class SimpleSceneFlag(RewardTerm):
    """1.0 when every target was visible with χ ≤ ``threshold`` before the action, else 0.0.

    The paper's threshold is 0.2; the authors' code used 0.1. A stop is judged on this flag (a stop
    does not change the scene), and a push from a simple scene is redundant. χ of the targets must be
    finite (a NaN would otherwise read as "not simple"); other slots are ignored.
    """

    out_key = keys.SIMPLE_SCENE

    def __init__(self, threshold: float = 0.2):
        super().__init__()
        self.threshold = finite_number(self, "threshold (an overlap rate)", threshold, low=0.0, high=1.0)

    def compute(self, before, after) -> torch.Tensor:
        targets = required(self, before, keys.TARGET_MASK, "root")
        return is_simple_scene(self.measured(before, keys.OVERLAP, "root", targets), targets, self.threshold).float()

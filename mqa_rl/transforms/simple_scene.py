"""The simple-scene flag: the scene *before* the action already answers the question."""

from __future__ import annotations

import torch

from mqa_rl import keys
from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.functional import is_simple_scene


class SimpleSceneFlag(RewardTerm):
    """1.0 when every target was visible with χ ≤ ``threshold`` before the action, else 0.0.

    The paper's threshold is 0.2; the authors' code used 0.1. A stop is judged on this flag (a stop
    does not change the scene), and a push from a simple scene is redundant.
    """

    out_key = keys.SIMPLE_SCENE

    def __init__(self, threshold: float = 0.2):
        super().__init__()
        if not 0.0 <= threshold <= 1.0:
            raise ValueError(f"the simple-scene threshold is an overlap rate in [0, 1], got {threshold}")
        self.threshold = float(threshold)

    def compute(self, before, after) -> torch.Tensor:
        return is_simple_scene(before.get(keys.OVERLAP), before.get(keys.TARGET_MASK), self.threshold).float()

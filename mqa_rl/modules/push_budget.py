"""``PushBudget``: any policy, stopped after a fixed number of pushes (``evaluate_policy.py budget=k``)."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from mqa_rl import keys
from mqa_rl.envs import actions


class PushBudget(TensorDictModuleBase):
    """``policy``, but it stops once the episode has ``budget`` pushes (the env's ``push_count``).

    A diagnostic for policies that do not learn when to stop: the learned DQN policies either stop at once
    or push until ``max_pushes``, and a push after the targets are uncovered can cover them again."""

    def __init__(self, policy, budget: int):
        super().__init__()
        if budget < 0:
            raise ValueError(f"a push budget must be >= 0 pushes, got {budget}")
        self.policy, self.budget = policy, int(budget)
        self.in_keys = [*getattr(policy, "in_keys", []), keys.PUSH_COUNT]
        self.out_keys = [keys.ACTION]

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        tensordict = self.policy(tensordict)
        spent = tensordict.get(keys.PUSH_COUNT).reshape(tensordict.get(keys.ACTION).shape) >= self.budget
        tensordict.set(keys.ACTION, torch.where(spent, actions.STOP, tensordict.get(keys.ACTION)))
        return tensordict

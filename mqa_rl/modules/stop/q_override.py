"""Overriding a greedy Q policy's choice: its best allowed push, and writing the action taken.

Wrappers that decide stop-or-push themselves (``StopMargin``, ``LearnedStop``) share these so that the
masked-push convention (masked actions carry the dtype's min) and ``chosen_action_value`` stay in one place.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase

from mqa_rl import keys
from mqa_rl.envs import actions


def best_allowed_push(q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(value, index, any allowed) of the best push in action values ``q`` [..., NUM_ACTIONS]."""
    value, index = q[..., : actions.STOP].max(dim=-1)
    return value, index, value > torch.finfo(q.dtype).min


def take_action(tensordict: TensorDictBase, q: torch.Tensor, chosen: torch.Tensor) -> TensorDictBase:
    """Write ``chosen`` as the action, and its Q value as ``chosen_action_value`` when the policy wrote one."""
    tensordict.set(keys.ACTION, chosen)
    if keys.CHOSEN_ACTION_VALUE in tensordict.keys():
        old = tensordict.get(keys.CHOSEN_ACTION_VALUE)
        tensordict.set(keys.CHOSEN_ACTION_VALUE, q.gather(-1, chosen.reshape(*q.shape[:-1], 1)).reshape(old.shape))
    return tensordict

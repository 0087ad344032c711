"""``StopMargin``: a greedy Q policy that stops only when stopping beats its best push by a margin (the
``stop_margin`` of a dqn system, ``evaluate_policy.py stop_margin=``)."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.modules.stop.q_override import best_allowed_push, take_action


class StopMargin(TensorDictModuleBase):
    """A greedy Q policy that stops only when Q(stop) beats its best allowed push by ``margin``.

    Imitation students learn "easy-looking scene -> stop" (97 % of easy episodes stop at once) while their
    push branch is the part that transfers; a margin > 0 trades stops for the best push. The margin is a
    decision threshold to choose on the training split (recipes/evaluate_policy.py split=train), never on
    the test split. ``margin=inf`` never stops (the env's push limit ends the episode)."""

    def __init__(self, policy, margin: float):
        super().__init__()
        if margin != margin:
            raise ValueError("stop_margin is NaN; give a number (0 = plain greedy, inf = never stop)")
        self.policy, self.margin = policy, float(margin)
        self.in_keys = list(getattr(policy, "in_keys", []))
        self.out_keys = list(getattr(policy, "out_keys", [keys.ACTION]))

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        tensordict = self.policy(tensordict)
        q = tensordict.get(keys.ACTION_VALUE)
        best_push_q, best_push, any_push = best_allowed_push(q)    # a scene with no allowed push keeps stopping
        stop_wins = q[..., actions.STOP] >= best_push_q + self.margin
        action = tensordict.get(keys.ACTION)
        chosen = torch.where((action == actions.STOP) & any_push & ~stop_wins, best_push.reshape(action.shape), action)
        return take_action(tensordict, q, chosen)       # Q of the action taken, not of the overruled stop

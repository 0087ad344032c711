"""``MQAReward``: the paper's reward from its terms (Sec. IV-A3).

    stop,  simple scene   → +1            (``stop_reward``)
    stop,  cluttered      → −1            (``early_stop_penalty``)
    push,  simple scene   →  0            (``redundant_push_reward``)
    push,  cluttered      → β · R_e + (1 − β) · R_q,   R_q = Σ_k w_k · term_k

"Simple" is judged on the scene before the action (``SimpleSceneFlag``), R_e, β and the R_q terms
are read from ``"reward_terms"``: put their transforms before this one.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data import Unbounded
from torchrl.envs import Transform

from mqa_rl import keys


class MQAReward(Transform):
    def __init__(
        self,
        question_weights: dict[str, float],
        *,
        stop_reward: float = 1.0,
        early_stop_penalty: float = -1.0,
        redundant_push_reward: float = 0.0,
    ):
        if not question_weights:
            raise ValueError("question_weights is empty: name at least one term, e.g. {'local_occlusion': 1.0}")
        self.question_weights = {str(k): float(v) for k, v in question_weights.items()}
        self._term_keys = [(keys.REWARD_TERMS, k) for k in self.question_weights]
        super().__init__(in_keys=[keys.EXPLORATION, keys.BETA, keys.SIMPLE_SCENE, keys.IS_STOP, *self._term_keys],
                         out_keys=[keys.REWARD])
        self.stop_reward = float(stop_reward)
        self.early_stop_penalty = float(early_stop_penalty)
        self.redundant_push_reward = float(redundant_push_reward)

    def question_reward(self, after: TensorDictBase) -> torch.Tensor:
        """R_q = Σ_k w_k · term_k, [..., 1]."""
        total = None
        for (key, w) in zip(self._term_keys, self.question_weights.values()):
            if key not in after.keys(True):
                raise KeyError(f"reward term {key[1]!r} is missing: add its transform before MQAReward "
                               f"(terms present: {sorted(after.get(keys.REWARD_TERMS).keys())})")
            term = w * after.get(key)
            total = term if total is None else total + term
        return total

    def reward(self, after: TensorDictBase) -> torch.Tensor:
        beta = after.get(keys.BETA)
        push = beta * after.get(keys.EXPLORATION) + (1 - beta) * self.question_reward(after)
        simple = after.get(keys.SIMPLE_SCENE) > 0.5
        stop = after.get(keys.IS_STOP)
        stop_r = torch.where(simple, torch.full_like(push, self.stop_reward), torch.full_like(push, self.early_stop_penalty))
        push_r = torch.where(simple, torch.full_like(push, self.redundant_push_reward), push)
        return torch.where(stop, stop_r, push_r)

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        next_tensordict.set(keys.REWARD, self.reward(next_tensordict))
        return next_tensordict

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """On a stored transition: rewrites ``("next", "reward")`` from the stored terms."""
        nxt = tensordict.get("next")
        nxt.set(keys.REWARD, self.reward(nxt))
        return tensordict

    def _inv_call(self, tensordict: TensorDictBase) -> TensorDictBase:
        return tensordict

    def _reset(self, tensordict, tensordict_reset):
        return tensordict_reset

    def transform_reward_spec(self, reward_spec):
        reward_spec[keys.REWARD] = Unbounded(shape=(*reward_spec.shape, 1), dtype=torch.float32, device=reward_spec.device)
        return reward_spec

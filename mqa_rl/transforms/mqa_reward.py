"""``MQAReward``: the paper's reward from its terms (Sec. IV-A3).

    stop,  simple scene   → +1            (``stop_reward``)
    stop,  cluttered      → −1            (``early_stop_penalty``)
    push,  simple scene   →  0            (``redundant_push_reward``)
    push,  cluttered      → β · R_e + (1 − β) · R_q,   R_q = Σ_k w_k · term_k
                                (``explore_key``: another term in R_e's place, e.g. R_s)
    then, with ``clip=(lo, hi)``, the total clamped to [lo, hi] (applied on stored transitions too)

"Simple" is judged on the scene before the action (``SimpleSceneFlag``), R_e, β and the R_q terms
are read from ``"reward_terms"``: put their transforms before this one. The flag must be finite on
every step; R_e, β and the weighted terms only where they are used (a push in a cluttered scene):
elsewhere they may hold anything. A non-finite value that counts raises ``ValueError``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch
from tensordict import TensorDictBase
from torchrl.data import Unbounded
from torchrl.envs import Transform

from mqa_rl import keys
from mqa_rl.transforms.checks import finite_number, finite_where, next_state, required

ADD_THE_TERM = "add its transform before MQAReward (make_reward_transform does)"


class MQAReward(Transform):
    def __init__(
        self,
        question_weights: dict[str, float],
        *,
        stop_reward: float = 1.0,
        early_stop_penalty: float = -1.0,
        redundant_push_reward: float = 0.0,
        clip: tuple[float, float] | None = None,
        explore_key=keys.EXPLORATION,
    ):
        if not isinstance(question_weights, Mapping) or not question_weights:
            raise ValueError(f"MQAReward: question_weights must name at least one term with its weight, e.g. "
                             f"{{'local_occlusion': 1.0}}; got {question_weights!r}")
        self.question_weights = {str(k): finite_number(self, f"question_weights[{k!r}]", v) for k, v in question_weights.items()}
        self._term_keys = [(keys.REWARD_TERMS, k) for k in self.question_weights]
        self.explore_key = explore_key
        super().__init__(in_keys=[explore_key, keys.BETA, keys.SIMPLE_SCENE, keys.IS_STOP, *self._term_keys],
                         out_keys=[keys.REWARD])
        self.stop_reward = finite_number(self, "stop_reward", stop_reward)
        self.early_stop_penalty = finite_number(self, "early_stop_penalty", early_stop_penalty)
        self.redundant_push_reward = finite_number(self, "redundant_push_reward", redundant_push_reward)
        self.clip = None
        if clip is not None:
            ok = isinstance(clip, Sequence) and not isinstance(clip, str) and len(clip) == 2
            low, high = (finite_number(self, "reward_clip bounds", v) for v in clip) if ok else (0.0, 0.0)
            if not ok or low >= high:
                raise ValueError(f"MQAReward: reward_clip must be null or [low, high] with low < high, got {clip!r}")
            self.clip = (low, high)

    def _used(self, after: TensorDictBase, key, counted: torch.Tensor) -> torch.Tensor:
        """A term, finite where ``counted``; where not, 0 (so a NaN there cannot leak through w · term)."""
        value = finite_where(self, required(self, after, key, "next", ADD_THE_TERM), counted, key, "next")
        return torch.where(counted, value, torch.zeros_like(value))

    def question_reward(self, after: TensorDictBase, counted: torch.Tensor | None = None) -> torch.Tensor:
        """R_q = Σ_k w_k · term_k, [..., 1] (``counted``: the steps it is used for; default all)."""
        if counted is None:
            counted = torch.ones(*after.batch_size, 1, dtype=torch.bool, device=after.device)
        total = None
        for (key, w) in zip(self._term_keys, self.question_weights.values()):
            term = w * self._used(after, key, counted)
            total = term if total is None else total + term
        return total

    def reward(self, after: TensorDictBase) -> torch.Tensor:
        simple = finite_where(self, required(self, after, keys.SIMPLE_SCENE, "next", ADD_THE_TERM), None,
                              keys.SIMPLE_SCENE, "next") > 0.5
        stop = required(self, after, keys.IS_STOP, "next").bool()
        used = ~stop & ~simple
        beta = self._used(after, keys.BETA, used)
        push = beta * self._used(after, self.explore_key, used) + (1 - beta) * self.question_reward(after, used)
        stop_r = torch.where(simple, torch.full_like(push, self.stop_reward), torch.full_like(push, self.early_stop_penalty))
        push_r = torch.where(simple, torch.full_like(push, self.redundant_push_reward), push)
        total = torch.where(stop, stop_r, push_r)
        return total if self.clip is None else total.clamp(*self.clip)

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        next_tensordict.set(keys.REWARD, self.reward(next_tensordict))
        return next_tensordict

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """On a stored transition: rewrites ``("next", "reward")`` from the stored terms."""
        nxt = next_state(self, tensordict)
        nxt.set(keys.REWARD, self.reward(nxt))
        return tensordict

    def _inv_call(self, tensordict: TensorDictBase) -> TensorDictBase:
        return tensordict

    def _reset(self, tensordict, tensordict_reset):
        return tensordict_reset

    def transform_reward_spec(self, reward_spec):
        reward_spec[keys.REWARD] = Unbounded(shape=(*reward_spec.shape, 1), dtype=torch.float32, device=reward_spec.device)
        return reward_spec

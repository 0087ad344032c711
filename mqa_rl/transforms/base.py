"""``RewardTerm``: the shape every reward term shares.

A term reads the state before an action (the root of a transition) and after it (``"next"``) and
writes one float32 [1] entry under ``"reward_terms"``. It is declared in the observation spec, so
collectors keep it, and written as 0 after a reset (there is no transition yet). The same object
works on a live env (``_step``) and on stored transitions, e.g. in a replay buffer's transforms
(``forward``: reads root and ``"next"``, writes into ``"next"``), so a replay buffer can re-score
stored data with another reward variant.

Inputs are read with ``measured`` / ``required`` (``mqa_rl.transforms.checks``): a missing key names
the term and the key; a NaN or inf in a slot that counts raises ``ValueError``; excluded slots are ignored.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data import Unbounded
from torchrl.envs import Transform

from mqa_rl.transforms.checks import finite_where, next_state, required


class RewardTerm(Transform):
    """Subclasses set ``out_key`` and implement ``compute(before, after) -> [..., 1]``."""

    out_key: tuple[str, str]

    def __init__(self):
        super().__init__(in_keys=[], out_keys=[self.out_key])

    def compute(self, before: TensorDictBase, after: TensorDictBase) -> torch.Tensor:
        raise NotImplementedError

    def measured(self, td: TensorDictBase, key, where: str, counted: torch.Tensor) -> torch.Tensor:
        """``td[key]`` (``where``: "root" = before the action, "next" = after), finite where ``counted``."""
        return finite_where(self, required(self, td, key, where), counted, key, where)

    def _write(self, before: TensorDictBase, after: TensorDictBase) -> TensorDictBase:
        value = self.compute(before, after)
        after.set(self.out_key, value.to(torch.float32).reshape(*after.batch_size, 1))
        return after

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        return self._write(tensordict, next_tensordict)

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        tensordict_reset.set(self.out_key, torch.zeros(*tensordict_reset.batch_size, 1, device=tensordict_reset.device))
        return tensordict_reset

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """On a stored transition (root = before, ``"next"`` = after)."""
        self._write(tensordict, next_state(self, tensordict))
        return tensordict

    def _inv_call(self, tensordict: TensorDictBase) -> TensorDictBase:
        return tensordict

    def transform_observation_spec(self, observation_spec):
        observation_spec[self.out_key] = Unbounded(shape=(*observation_spec.shape, 1), dtype=torch.float32,
                                                   device=observation_spec.device)
        return observation_spec

"""The paper's random baseline: random pushes, and a random number of them.

"Both the manipulation action and the number of manipulation are randomly selected" (Sec. V-A).
Stateless: at push count k the policy stops with probability 1 / (M + 1 − k), which makes the number
of pushes before stop uniform on {0, …, M} (M = the env's ``max_pushes``); otherwise it pushes at a
uniformly random cell and direction.

``masked=True`` draws pushes only among those the observation's ``action_mask`` allows (the
learned policy's action set), a stronger baseline than the paper's.

With ``seed`` the policy draws from its own generator (reproducible in one process); collector
workers receive copies of it, so leave ``seed=None`` there to draw from each worker's own global
torch RNG (the workers would otherwise repeat each other's actions).
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from mqa_rl import keys
from mqa_rl.envs import actions


class RandomMQAPolicy(TensorDictModuleBase):
    in_keys = [keys.PUSH_COUNT]
    out_keys = [keys.ACTION]

    def __init__(self, max_pushes: int = 10, seed: int | None = None, masked: bool = False):
        super().__init__()
        self.masked = masked
        if masked:
            self.in_keys = [keys.PUSH_COUNT, keys.ACTION_MASK]
        if max_pushes < 1:
            raise ValueError(f"max_pushes must be ≥ 1, got {max_pushes}")
        # a buffer, not a plain int: collectors share policy state with their workers, and a
        # module without any tensor state makes that sharing fail
        self.register_buffer("max_pushes", torch.tensor(max_pushes, dtype=torch.int64))
        self.seed = seed
        self._generator: torch.Generator | None = None

    def __getstate__(self):
        # torch.Generator does not survive the trip to collector workers: recreate it from the seed
        state = super().__getstate__() if hasattr(super(), "__getstate__") else self.__dict__.copy()
        state = dict(state)
        state["_generator"] = None
        return state

    @property
    def generator(self) -> torch.Generator | None:
        if self.seed is not None and self._generator is None:
            self._generator = torch.Generator().manual_seed(self.seed)
        return self._generator

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        k = tensordict.get(keys.PUSH_COUNT).squeeze(-1)
        p_stop = 1.0 / (self.max_pushes + 1 - k).clamp(min=1).to(torch.float32)
        stop = torch.rand(k.shape, generator=self.generator) < p_stop
        if self.masked:
            allowed = tensordict.get(keys.ACTION_MASK)[..., : actions.NUM_PUSHES].reshape(-1, actions.NUM_PUSHES)
            push = torch.multinomial(allowed.float(), 1, generator=self.generator).reshape(k.shape)
        else:
            push = torch.randint(0, actions.NUM_PUSHES, k.shape, generator=self.generator)
        tensordict.set(keys.ACTION, torch.where(stop, torch.full_like(push, actions.STOP), push))
        return tensordict

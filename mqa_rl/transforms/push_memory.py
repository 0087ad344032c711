"""PushMemory: the action mask forgets no push made earlier in the episode.

A Q-network that sees only the current image is deterministic in it: when a push barely changes the
scene (an object pressed against the wall, a push that slides past), the next image is nearly the same
and the greedy policy makes the same push again, until ``max_pushes``. Measured on run E's greedy policy
(hard test scenes, 20 episodes): 38 % of its pushes repeated the previous one exactly, and half the
episodes had three identical pushes in a row. The paper's agent has the same blind spot; its teacher here
(``PrivilegedPushPolicy``) tries an occluder at most twice.

This transform carries the episode's pushes as an observation, ``pushed`` (bool over the pushes; the
push itself and the pushes of the same direction starting within ``radius`` grid cells of it), and
removes them from the next ``action_mask``: greedy and ε-greedy choose among the pushes not yet made;
stop stays allowed. Cleared at reset. State lives in the tensordict (like ``EpisodeStats``), so it
works in batched envs, collectors and replay.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from tensordict import TensorDictBase
from torchrl.data import Binary, Composite
from torchrl.envs import Transform

from mqa_rl import keys
from mqa_rl.envs import actions


def memory_radius(override, run_env) -> int | None:
    """The push memory an evaluation or stop fit runs with: ``override`` (a recipe's ``push_memory``) unless
    None, else the run's ``env.push_memory``; None or a negative radius: no memory."""
    radius = override if override is not None else (run_env.get("push_memory") if run_env is not None else None)
    return None if radius is None or int(radius) < 0 else int(radius)


class PushMemory(Transform):
    def __init__(self, radius: int = 1):
        if radius < 0:
            raise ValueError(f"push_memory radius must be ≥ 0 grid cells, got {radius}")
        self.radius = int(radius)
        super().__init__(in_keys=[keys.ACTION_MASK], out_keys=[keys.PUSHED])

    def _reset(self, tensordict, tensordict_reset):
        pushed = torch.zeros(*tensordict_reset.batch_size, actions.NUM_PUSHES, dtype=torch.bool,
                             device=tensordict_reset.device)
        tensordict_reset.set(keys.PUSHED, pushed)
        return tensordict_reset

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        pushed = tensordict.get(keys.PUSHED) | self._neighbourhood(tensordict.get(keys.ACTION))
        next_tensordict.set(keys.PUSHED, pushed)
        mask = next_tensordict.get(keys.ACTION_MASK).clone()
        mask[..., : actions.NUM_PUSHES] &= ~pushed
        next_tensordict.set(keys.ACTION_MASK, mask)
        return next_tensordict

    def _neighbourhood(self, action: torch.Tensor) -> torch.Tensor:
        """bool [*B, NUM_PUSHES]: each push action with its same-direction neighbours; nothing for stop."""
        flat = action.reshape(-1)
        hit = torch.zeros(len(flat), actions.NUM_ACTIONS, device=flat.device)
        hit[torch.arange(len(flat)), flat] = 1.0
        grid = hit[:, : actions.NUM_PUSHES].view(-1, actions.DIRECTIONS, actions.GRID, actions.GRID)
        if self.radius:
            grid = F.max_pool2d(grid, 2 * self.radius + 1, 1, self.radius)
        return grid.reshape(*action.shape, actions.NUM_PUSHES) > 0

    def transform_observation_spec(self, spec: Composite) -> Composite:
        spec[keys.PUSHED] = Binary(n=actions.NUM_PUSHES, shape=(*spec.shape, actions.NUM_PUSHES),
                                   dtype=torch.bool, device=spec.device)
        return spec

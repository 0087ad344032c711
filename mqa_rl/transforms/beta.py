"""β annealing: the weight of exploration against question-driven reward, decaying with training."""

from __future__ import annotations

import math

import torch

from mqa_rl import keys
from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.checks import finite_number
from mqa_rl.transforms.functional import beta_schedule


class BetaSchedule(RewardTerm):
    """Writes β = 1 − (1 − β_T) · S_n / T (then β_T) for every step; S_n is the DQN training-step count.

    β_T (``final``) is the paper's 0.5 by default: half of every push reward stays R_e for ever.

    ``counter`` is the int64 scalar holding S_n. The training loop advances it (``set_train_steps``).
    To reach env copies in collector worker processes, create it once with
    ``torch.zeros((), dtype=torch.int64).share_memory_()`` and hand the same tensor to every env
    factory through the collector's ``create_env_kwargs`` (a closure or ``functools.partial`` is
    pickled by value: the workers would get a frozen copy). It is a buffer, so it is saved in the
    transform's ``state_dict`` and a resumed run continues the schedule (loading copies in place and
    keeps the sharing).
    """

    out_key = keys.BETA

    def __init__(self, horizon: int, counter: torch.Tensor | None = None, final: float = 0.5):
        super().__init__()
        horizon = finite_number(self, "horizon T (half the replay memory)", horizon, positive=True)
        self.final = finite_number(self, "final β", final, low=0.0, high=1.0)
        if counter is None:
            counter = torch.zeros((), dtype=torch.int64)
        if not isinstance(counter, torch.Tensor) or counter.dtype != torch.int64 or counter.numel() != 1:
            raise ValueError(f"BetaSchedule: the step counter must be an int64 scalar tensor, got {counter!r}")
        self.horizon = int(horizon) if horizon.is_integer() else horizon
        self.register_buffer("train_steps", counter)

    def set_train_steps(self, steps: int) -> None:
        self.train_steps.fill_(int(steps))

    @property
    def beta(self) -> float:
        return float(beta_schedule(self.train_steps, self.horizon, self.final))

    def compute(self, before, after) -> torch.Tensor:
        beta = beta_schedule(self.train_steps, self.horizon, self.final).to(after.device)
        return beta.expand(*after.batch_size, 1)

    def _reset(self, tensordict, tensordict_reset):
        tensordict_reset.set(self.out_key, self.compute(None, tensordict_reset))
        return tensordict_reset


def trained_counter(reward: dict) -> torch.Tensor:
    """β's step counter at the end of its schedule (β = β_T): the reward a trained policy was trained towards, for
    evaluations (a fresh counter would report β = 1: R_e and the stop terms alone)."""
    return torch.tensor(math.ceil(float(reward.get("beta_horizon", 2000))), dtype=torch.int64)

"""Running episode statistics as observations, so that a collector's batch tells at every episode
end what the episode earned: reward and reward-term sums, the targets' mean overlap χ at reset and
which targets were in view then (what a counter could count on the first image).

Put it after the reward stack. Sums run from the reset; the values at a step with ``done`` describe
the finished episode (``mqa_rl.evaluation.episode_metrics`` turns them into metrics).
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data import Composite, Unbounded
from torchrl.envs import Transform

from mqa_rl import keys

# A target counts as in view with at least this many visible pixels: the line of the answering
# evaluation's perfect counter (mqa_rl.evaluation.answering.counter_right).
COUNTABLE_PX = 20.0


def mean_target_chi(td: TensorDictBase) -> torch.Tensor:
    """Mean χ of the question's targets, [..., 1]; 0 where there is no target."""
    t = td.get(keys.TARGET_MASK).to(torch.float32)
    chi = td.get(keys.OVERLAP)
    return ((chi * t).sum(-1) / t.sum(-1).clamp(min=1)).unsqueeze(-1)


def targets_in_view(td: TensorDictBase) -> torch.Tensor:
    """bool [..., K]: the question's targets with at least ``COUNTABLE_PX`` visible pixels."""
    return td.get(keys.TARGET_MASK) & (td.get(keys.VISIBLE_AREA) >= COUNTABLE_PX)


def uncountable_share(td: TensorDictBase) -> torch.Tensor:
    """[...]: the share of the question's targets below the perfect counter's line (0 without targets)."""
    targets = td.get(keys.TARGET_MASK)
    missed = (targets & ~targets_in_view(td)).sum(-1).to(torch.float32)
    return missed / targets.sum(-1).clamp(min=1)


class EpisodeStats(Transform):
    def __init__(self, terms: tuple[str, ...] = ()):
        self.terms = tuple(terms)
        self._term_keys = [(keys.REWARD_TERMS, t) for t in self.terms]
        out = [keys.EPISODE_REWARD, keys.TARGET_CHI_START, keys.TARGETS_IN_VIEW_START,
               *((*keys.EPISODE_TERMS, t) for t in self.terms)]
        super().__init__(in_keys=[keys.REWARD, *self._term_keys], out_keys=out)

    def _zeros(self, td: TensorDictBase) -> torch.Tensor:
        return torch.zeros(*td.batch_size, 1, device=td.device)

    def _reset(self, tensordict, tensordict_reset):
        tensordict_reset.set(keys.EPISODE_REWARD, self._zeros(tensordict_reset))
        for t in self.terms:
            tensordict_reset.set((*keys.EPISODE_TERMS, t), self._zeros(tensordict_reset))
        tensordict_reset.set(keys.TARGET_CHI_START, mean_target_chi(tensordict_reset))
        tensordict_reset.set(keys.TARGETS_IN_VIEW_START, targets_in_view(tensordict_reset))
        return tensordict_reset

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        next_tensordict.set(keys.EPISODE_REWARD, tensordict.get(keys.EPISODE_REWARD) + next_tensordict.get(keys.REWARD))
        for t, key in zip(self.terms, self._term_keys):
            total = (*keys.EPISODE_TERMS, t)
            next_tensordict.set(total, tensordict.get(total) + next_tensordict.get(key))
        next_tensordict.set(keys.TARGET_CHI_START, tensordict.get(keys.TARGET_CHI_START))
        next_tensordict.set(keys.TARGETS_IN_VIEW_START, tensordict.get(keys.TARGETS_IN_VIEW_START))
        return next_tensordict

    def transform_observation_spec(self, spec: Composite) -> Composite:
        scalar = Unbounded(shape=(*spec.shape, 1), dtype=torch.float32, device=spec.device)
        terms = Composite({t: scalar.clone() for t in self.terms}, shape=spec.shape, device=spec.device)
        in_view = spec[keys.TARGET_MASK].clone()
        spec[keys.EPISODE] = Composite(reward=scalar.clone(), terms=terms, target_chi_start=scalar.clone(),
                                       targets_in_view_start=in_view, shape=spec.shape, device=spec.device)
        return spec

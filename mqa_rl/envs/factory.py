"""``make_mqa_env``: SapienBinEnv plus a reward stack, as recipes and collector workers build it.

Module-level and keyword-driven so that process-based collectors can pickle it; pass the shared β
step counter through the collector's ``create_env_kwargs`` (see ``BetaSchedule``).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torchrl.envs import TransformedEnv

from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.transforms.factory import make_reward_transform


def make_mqa_env(dataset, reward: Mapping | None = None, counter: torch.Tensor | None = None, **env_kwargs):
    """``SapienBinEnv(dataset, **env_kwargs)``, wrapped with ``make_reward_transform(reward)`` if given."""
    env = SapienBinEnv(dataset, **env_kwargs)
    if reward is None:
        return env
    return TransformedEnv(env, make_reward_transform(reward, push_length=env.push_length, counter=counter))

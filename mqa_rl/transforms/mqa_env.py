"""``make_mqa_env``: SapienBinEnv plus a reward stack, as recipes and collector workers build it.

It lives above the env (in ``transforms``, not ``envs``) because it composes the reward transforms:
the env measures and imports nothing from the reward package.

Module-level and keyword-driven so that process-based collectors can pickle it; pass the shared β
step counter through the collector's ``create_env_kwargs`` (see ``BetaSchedule``).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torchrl.envs import TransformedEnv

from mqa_rl import keys
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.episode_stats import EpisodeStats
from mqa_rl.transforms.factory import make_reward_transform
from mqa_rl.transforms.push_memory import PushMemory


def make_mqa_env(dataset, reward: Mapping | None = None, counter: torch.Tensor | None = None,
                 episode_stats: bool = False, push_memory: int | None = None, **env_kwargs):
    """``SapienBinEnv(dataset, **env_kwargs)``, wrapped with ``make_reward_transform(reward)`` if given,
    with ``EpisodeStats`` over the reward and its terms when ``episode_stats`` (training, evaluation), and
    with ``PushMemory(push_memory)`` (no push twice in an episode; the radius in grid cells) unless None."""
    env = SapienBinEnv(dataset, **env_kwargs)
    memory = PushMemory(push_memory) if push_memory is not None else None
    if reward is None:
        return env if memory is None else TransformedEnv(env, memory)
    stack = make_reward_transform(reward, push_length=env.push_length, counter=counter)
    if episode_stats:           # sum the reward terms (not β nor the simple-scene flag) over episodes
        summed = [t.out_key[1] for t in stack if isinstance(t, RewardTerm) and t.out_key not in (keys.BETA, keys.SIMPLE_SCENE)]
        stack.append(EpisodeStats(tuple(summed)))
    if memory is not None:
        stack.append(memory)
    return TransformedEnv(env, stack)

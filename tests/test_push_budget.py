"""PushBudget: a policy that stops once its episode has made ``budget`` pushes."""

import pytest
import torch
from tensordict import TensorDictBase

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.modules.push_budget import PushBudget
from mqa_rl.transforms.mqa_env import make_mqa_env
from torch_threads import one_torch_thread  # noqa: F401  (autouse)


class FirstAllowedPush:
    """Always the first push the action mask allows (never stops on its own)."""

    def __call__(self, td: TensorDictBase) -> TensorDictBase:
        td.set(keys.ACTION, td[keys.ACTION_MASK][: actions.NUM_PUSHES].nonzero()[0, 0])
        return td


@pytest.mark.parametrize("budget", [0, 2])
def test_the_policy_stops_after_its_budget(small_dataset, budget):
    env = make_mqa_env(small_dataset, None, split=None, seed=0, max_pushes=4)
    rollout = env.rollout(6, PushBudget(FirstAllowedPush(), budget), break_when_any_done=True)
    chosen = rollout[keys.ACTION].tolist()
    assert actions.STOP not in chosen[:budget]
    assert chosen[budget:] == [actions.STOP]           # stopped (not truncated at max_pushes)
    assert int(rollout["next", *keys.PUSH_COUNT][-1]) == budget


def test_a_negative_budget_is_refused():
    with pytest.raises(ValueError, match="budget"):
        PushBudget(FirstAllowedPush(), -1)

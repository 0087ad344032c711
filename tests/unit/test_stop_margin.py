"""StopMargin: a greedy Q policy that stops only when Q(stop) beats its best allowed push by a margin."""

import math

import pytest
import torch
from tensordict import TensorDict
from torchrl.modules import QValueModule

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.modules.stop.stop_margin import StopMargin
from torch_threads import one_torch_thread  # noqa: F401  (autouse)


def greedy():
    return QValueModule(action_space="categorical", action_value_key=keys.ACTION_VALUE,
                        action_mask_key=keys.ACTION_MASK)


def state(push_values: dict[int, float], stop_value: float, masked=()):
    """Action values with a few pushes set (all others far below), the given pushes masked out."""
    q = torch.full((2, actions.NUM_ACTIONS), -10.0)     # a batch of two identical states
    for push, value in push_values.items():
        q[:, push] = value
    q[:, actions.STOP] = stop_value
    mask = torch.ones(2, actions.NUM_ACTIONS, dtype=torch.bool)
    mask[:, list(masked)] = False
    return TensorDict({keys.ACTION_VALUE: q, keys.ACTION_MASK: mask}, batch_size=[2])


def test_margin_zero_is_the_greedy_policy():
    td = StopMargin(greedy(), 0.0)(state({5: 1.0}, stop_value=1.2))
    assert td[keys.ACTION].tolist() == [actions.STOP, actions.STOP]


def test_a_stop_that_does_not_beat_the_best_push_by_the_margin_becomes_that_push():
    td = StopMargin(greedy(), 0.5)(state({5: 1.0, 900: 0.9}, stop_value=1.2))
    assert td[keys.ACTION].tolist() == [5, 5]
    assert td[keys.CHOSEN_ACTION_VALUE].flatten().tolist() == [1.0, 1.0]     # the push's value, not the stop's
    td = StopMargin(greedy(), 0.1)(state({5: 1.0}, stop_value=1.2))      # beats it by 0.2 > 0.1: stops
    assert td[keys.ACTION].tolist() == [actions.STOP, actions.STOP]


def test_the_replacement_push_is_an_allowed_one():
    td = StopMargin(greedy(), math.inf)(state({5: 1.0, 900: 0.9}, stop_value=1.2, masked=[5]))
    assert td[keys.ACTION].tolist() == [900, 900]


def test_a_scene_without_allowed_pushes_still_stops():
    td = StopMargin(greedy(), math.inf)(state({}, stop_value=1.0, masked=range(actions.NUM_PUSHES)))
    assert td[keys.ACTION].tolist() == [actions.STOP, actions.STOP]


def test_a_push_chosen_by_the_policy_is_kept():
    td = StopMargin(greedy(), 0.5)(state({5: 2.0}, stop_value=1.0))
    assert td[keys.ACTION].tolist() == [5, 5]


def test_a_nan_margin_is_refused():
    with pytest.raises(ValueError, match="NaN"):
        StopMargin(greedy(), float("nan"))

"""SapienBinEnv's step / reset contract: no step after done, integer-only indices, specs always hold."""

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tensordict import TensorDict
from torchrl.envs import TransformedEnv

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.transforms.push_memory import PushMemory

CHEAP = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def env(sparse_dataset):
    return SapienBinEnv(sparse_dataset, split=None, seed=0, max_pushes=2, image_size=112)


def _step(env, td, action):
    td = td.clone()
    td[keys.ACTION] = action if isinstance(action, torch.Tensor) else torch.tensor(action)
    return env.step(td)["next"]


def _in_specs(env, td):
    for spec in (env.observation_spec, env.done_spec):
        for key in spec.keys(True, True):
            assert spec[key].is_in(td[key]), (key, td[key])
    return True


def test_step_after_stop_raises_until_reset(env):
    td = env.reset()
    out = _step(env, td, actions.STOP)
    assert out["done"].item()
    for action in (actions.encode(0, 14, 14), actions.STOP):
        with pytest.raises(RuntimeError, match=r"call reset\(\)"):
            _step(env, out, action)
    out = _step(env, env.reset(), actions.encode(0, 14, 14))
    assert not out["done"].item() and out[keys.PUSH_COUNT].item() == 1


def test_step_after_truncation_raises_and_push_count_stays_in_its_spec(env):
    td = env.reset()
    for k in range(2):
        td = _step(env, td, actions.encode(k, 14, 14))
    assert td["truncated"].item() and td[keys.PUSH_COUNT].item() == 2
    for _ in range(2):
        with pytest.raises(RuntimeError, match="episode is over"):
            _step(env, td, actions.encode(3, 14, 14))
    assert _in_specs(env, td)


def test_rollout_without_breaking_on_done_resets_by_itself(env):
    policy = lambda td: td.set(keys.ACTION, torch.tensor(actions.STOP))   # noqa: E731  every step ends the episode
    r = env.rollout(3, policy, break_when_any_done=False)
    assert r["next", "done"].all() and r.shape == (3,)


@pytest.mark.parametrize("value", [torch.tensor([3.7]), torch.tensor([True]), torch.tensor([1, 2]), torch.tensor([10**9])])
def test_reset_question_must_be_one_integer_in_range(env, value):
    with pytest.raises(ValueError, match="reset_question"):
        env.reset(env.reset().empty().set(keys.RESET_QUESTION, value))


def test_reset_question_reaches_the_env_through_transforms(env):
    # TransformedEnv passes on only the reset keys and declared state: reset_question is declared state.
    wrapped = TransformedEnv(env, PushMemory(1))
    for index in (1, 0, len(env.dataset.questions) - 1):
        td = wrapped.reset(TensorDict({keys.RESET_QUESTION: torch.tensor([index])}, []))
        assert env.question.id == env.dataset.questions[index].id
        assert td[keys.QUESTION_INDEX].item() == index
        assert td[keys.RESET_QUESTION].item() == -1      # an auto-reset from this state picks at random


def test_action_message_reads_naturally(env):
    td = env.reset()
    with pytest.raises(ValueError) as e:
        _step(env, td, torch.tensor([1, 2]))
    assert "must be one integer index in [0, 6273)" in str(e.value) and "an an" not in str(e.value)


action_values = st.one_of(
    st.integers(-10, actions.NUM_ACTIONS + 10), st.sampled_from([actions.STOP, actions.STOP - 1, 0]),
    st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
    st.lists(st.integers(0, actions.STOP), min_size=0, max_size=3),
)


@CHEAP
@given(st.lists(action_values, min_size=1, max_size=4))
def test_any_action_sequence_gives_a_clear_error_or_outputs_in_the_specs(env, values):
    td = env.reset()
    done = False
    for value in values:
        try:
            out = _step(env, td, torch.tensor(value))
        except RuntimeError as e:
            assert done and "reset()" in str(e)
            continue
        except ValueError as e:
            assert "action" in str(e)
            continue
        assert not done and _in_specs(env, out)
        assert torch.isfinite(out[keys.OBJECT_POS]).all() and torch.isfinite(out[keys.OVERLAP]).all()
        done, td = bool(out["done"].item()), out


@CHEAP
@given(st.one_of(st.integers(-3, 2**40), st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
                 st.lists(st.integers(0, 5), min_size=0, max_size=2)))
def test_any_reset_index_gives_a_clear_error_or_that_question(env, value):
    n = len(env.dataset.questions)
    index = value[0] if isinstance(value, list) and len(value) == 1 else value    # a one-element tensor is fine
    request = env.reset().empty().set(keys.RESET_QUESTION, torch.tensor(value))
    try:
        td = env.reset(request)
    except ValueError as e:
        assert "reset_question" in str(e)
        assert not (type(index) is int and index < n)
        return
    assert type(index) is int and index < n
    if index >= 0:
        assert td[keys.QUESTION_INDEX].item() == index
    assert _in_specs(env, td)

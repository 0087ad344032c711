"""The reward transforms on stored transitions: missing keys, masked slots, non-finite values, configs."""

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.transforms import (BetaSchedule, ExplorationReward, GlobalOcclusionReward, LocalOcclusionReward, MQAReward,
                               SimpleSceneFlag, make_reward_transform)

CFG = {"terms": {"global_occlusion": {}, "local_occlusion": {}},
       "question_weights": {"global_occlusion": 0.5, "local_occlusion": 0.5}}
STACK = make_reward_transform(CFG, push_length=0.12)
TERM_KEYS = (keys.EXPLORATION, keys.GLOBAL_OCCLUSION, keys.LOCAL_OCCLUSION, keys.SIMPLE_SCENE, keys.BETA, keys.REWARD)


def transition(seed: int, k: int = 6, batch=(), stop: bool = False) -> TensorDict:
    """A stored transition as the env writes it: objects in the first slots, padding after them."""
    g = torch.Generator().manual_seed(seed)
    n = torch.randint(0, k + 1, batch + (1,), generator=g)
    objects = torch.arange(k).expand(*batch, k) < n
    targets = objects & (torch.rand(*batch, k, generator=g) < 0.5)

    def info(pos):
        return {"object_pos": pos, "overlap": torch.rand(*batch, k, generator=g), "object_mask": objects,
                "target_mask": targets, "question_type": torch.randint(0, 4, batch + (1,), generator=g),
                "is_stop": torch.full(batch + (1,), stop)}

    pos = torch.rand(*batch, k, 3, generator=g) * 0.3
    after = pos + 0.05 * torch.randn(*batch, k, 3, generator=g)
    return TensorDict({keys.INFO: info(pos), "next": {keys.INFO: info(after)}}, batch_size=batch)


def scored(td):
    out = STACK(td.clone())["next"]
    return {key: out[key] for key in TERM_KEYS}


# ----------------------------------------------------------------------------------------- missing keys
@pytest.mark.parametrize("transform, key, named", [
    (ExplorationReward(0.12), keys.OBJECT_POS, '("info", "object_pos")'),
    (ExplorationReward(0.12), ("next", *keys.OBJECT_POS), '("next", "info", "object_pos")'),
    (GlobalOcclusionReward(), ("next", *keys.OVERLAP), '("next", "info", "overlap")'),
    (LocalOcclusionReward(), keys.TARGET_MASK, '("info", "target_mask")'),
    (SimpleSceneFlag(), keys.OVERLAP, '("info", "overlap")'),
    (GlobalOcclusionReward(), "next", '"next" entry'),
])
def test_a_missing_key_names_the_transform_and_the_key(transform, key, named):
    td = transition(0).exclude(key)
    with pytest.raises(KeyError, match=type(transform).__name__) as e:
        transform(td)
    assert named in str(e.value)


def test_mqa_reward_names_a_missing_stop_flag_or_term():
    td = STACK[:-1](transition(0))                          # every term, not yet the reward
    reward = STACK[-1]
    with pytest.raises(KeyError, match=r'MQAReward needs \("next", "info", "is_stop"\)'):
        reward(td.exclude(("next", *keys.IS_STOP)))
    with pytest.raises(KeyError, match=r'MQAReward needs \("next", "reward_terms", "local_occlusion"\).*before MQAReward'):
        reward(td.exclude(("next", *keys.LOCAL_OCCLUSION)))


# ----------------------------------------------------------------------------------------- non-finite values
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_measurement_in_a_counted_slot_is_an_error(bad):
    td = transition(1, batch=(4,))
    slot = td[keys.TARGET_MASK].nonzero()[0].tolist()
    td["next", *keys.OVERLAP][tuple(slot)] = bad
    with pytest.raises(ValueError, match=r'GlobalOcclusionReward: \("next", "info", "overlap"\) is NaN or infinite'):
        STACK(td)
    td = transition(1, batch=(4,))
    td[keys.OBJECT_POS][tuple(td[keys.OBJECT_MASK].nonzero()[0].tolist())] = bad
    with pytest.raises(ValueError, match=r'ExplorationReward: \("info", "object_pos"\) is NaN or infinite'):
        STACK(td)


def test_non_finite_term_counts_only_where_it_is_used():
    reward = MQAReward({"local_occlusion": 1.0})
    td = TensorDict({keys.BETA: torch.ones(2, 1), keys.EXPLORATION: torch.tensor([[0.3], [0.3]]),
                     keys.LOCAL_OCCLUSION: torch.tensor([[math.nan], [math.nan]]),
                     keys.SIMPLE_SCENE: torch.zeros(2, 1), keys.IS_STOP: torch.tensor([[True], [True]])}, [2])
    torch.testing.assert_close(reward.reward(td), torch.tensor([[-1.0], [-1.0]]))     # stops: R_l unused
    td[keys.IS_STOP][1] = False
    with pytest.raises(ValueError, match=r'MQAReward: \("next", "reward_terms", "local_occlusion"\)'):
        reward.reward(td)
    td[keys.SIMPLE_SCENE][0] = math.nan
    with pytest.raises(ValueError, match="simple_scene"):
        reward.reward(td)


anything = st.sampled_from([math.nan, math.inf, -math.inf, 1e30, -1e30, -5.0, 7.0])


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 2**31), st.integers(1, 8), st.sampled_from([(), (3,)]), st.booleans(), anything)
def test_slots_the_masks_exclude_never_matter(seed, k, batch, stop, junk):
    clean = transition(seed, k, batch, stop)
    dirty = clean.clone()
    for root in ((), ("next",)):
        pos, chi = dirty[(*root, *keys.OBJECT_POS)], dirty[(*root, *keys.OVERLAP)]
        pos[~clean[keys.OBJECT_MASK]] = junk
        chi[~clean[keys.TARGET_MASK]] = junk
    a, b = scored(clean), scored(dirty)
    for key in TERM_KEYS:
        assert torch.equal(a[key], b[key]), key
        assert torch.isfinite(a[key]).all()


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 2**31), st.integers(1, 8), st.sampled_from([(), (3,)]), st.booleans(),
       st.lists(st.tuples(st.booleans(), st.booleans(), st.integers(0, 2**20), anything), min_size=1, max_size=4))
def test_any_values_give_a_named_error_or_finite_rewards(seed, k, batch, stop, hits):
    """NaN / inf / huge values in random slots: ValueError exactly when a counted slot is non-finite."""
    td = transition(seed, k, batch, stop)
    for after, position, where, value in hits:
        key = (*(("next",) if after else ()), *(keys.OBJECT_POS if position else keys.OVERLAP))
        flat = td[key].reshape(-1, 3) if position else td[key].reshape(-1)
        flat[where % flat.shape[0]] = value
    counted_bad = any(
        bool((~torch.isfinite(td[(*root, *keys.OBJECT_POS)]).any(-1) & td[keys.OBJECT_MASK]).any()
             or (~torch.isfinite(td[(*root, *keys.OVERLAP)]) & td[keys.TARGET_MASK]).any())
        for root in ((), ("next",)))
    try:
        out = scored(td)
    except ValueError as e:
        assert counted_bad and "NaN or infinite" in str(e), e
        return
    assert not counted_bad
    for key in TERM_KEYS:
        assert torch.isfinite(out[key]).all(), key


# ----------------------------------------------------------------------------------------- configs
@pytest.mark.parametrize("make, named", [
    (lambda: MQAReward({"local_occlusion": math.nan}), r"MQAReward: question_weights\['local_occlusion'\]"),
    (lambda: MQAReward({"local_occlusion": math.inf}), r"MQAReward: question_weights"),
    (lambda: MQAReward({"local_occlusion": True}), r"MQAReward: question_weights"),
    (lambda: MQAReward({"local_occlusion": 1.0}, stop_reward=math.nan), "MQAReward: stop_reward"),
    (lambda: MQAReward({"local_occlusion": 1.0}, early_stop_penalty=-math.inf), "MQAReward: early_stop_penalty"),
    (lambda: MQAReward({"local_occlusion": 1.0}, redundant_push_reward="0"), "MQAReward: redundant_push_reward"),
    (lambda: MQAReward(["local_occlusion"]), "MQAReward: question_weights"),
    (lambda: ExplorationReward(0.12, cap=0), "ExplorationReward: cap"),
    (lambda: ExplorationReward(0.12, cap=-1.0), "ExplorationReward: cap"),
    (lambda: ExplorationReward(0.12, cap=math.nan), "ExplorationReward: cap"),
    (lambda: ExplorationReward(math.nan), "ExplorationReward: push_length"),
    (lambda: SimpleSceneFlag(math.nan), "SimpleSceneFlag: threshold"),
    (lambda: SimpleSceneFlag(1.5), "SimpleSceneFlag: threshold"),
    (lambda: BetaSchedule(math.nan), "BetaSchedule: horizon"),
    (lambda: BetaSchedule(0), "BetaSchedule: horizon"),
    (lambda: LocalOcclusionReward(3), "LocalOcclusionReward: reduce"),
    (lambda: make_reward_transform({"terms": {"local_occlusion": {"reduse": "min"}},
                                    "question_weights": {"local_occlusion": 1.0}}, push_length=0.12),
     r"reward term 'local_occlusion' \(LocalOcclusionReward\).*'reduse'.*takes \['reduce'\]"),
    (lambda: make_reward_transform({"terms": {"exploration": {"cap": 0}}, "question_weights": {"exploration": 1.0}},
                                   push_length=0.12), "ExplorationReward: cap"),
    (lambda: make_reward_transform({"terms": ["local_occlusion"]}, push_length=0.12), "terms must be a mapping"),
])
def test_bad_config_values_name_the_transform_and_parameter(make, named):
    with pytest.raises(ValueError, match=named):
        make()


def test_negative_weights_stay_allowed():
    reward = MQAReward({"local_occlusion": -2.0}, stop_reward=-0.5)
    td = TensorDict({keys.BETA: torch.tensor([0.5]), keys.EXPLORATION: torch.tensor([0.2]),
                     keys.LOCAL_OCCLUSION: torch.tensor([0.4]), keys.SIMPLE_SCENE: torch.tensor([0.0]),
                     keys.IS_STOP: torch.tensor([False])}, [])
    assert reward.reward(td).item() == pytest.approx(0.5 * 0.2 + 0.5 * -2.0 * 0.4)


@pytest.mark.parametrize("clip", [[1.0, -1.0], [0.0], "big", [True, 2.0]])
def test_reward_clip_config_is_checked(clip):
    from mqa_rl.transforms.factory import make_reward_transform
    with pytest.raises(ValueError, match="reward_clip"):
        make_reward_transform({"terms": {"local_occlusion": {}}, "question_weights": {"local_occlusion": 1.0},
                               "reward_clip": clip}, push_length=0.1)


def test_reward_clip_clamps_the_total():
    """R_e = 3 with β = 1 gives 1, R_l = −7 with β = 0 gives −1, a stop's −1 stays."""
    r = MQAReward({"local_occlusion": 1.0}, clip=[-1, 1])
    nxt = TensorDict({keys.EXPLORATION: torch.tensor([[3.0], [0.0], [0.0]]),
                      keys.BETA: torch.tensor([[1.0], [0.0], [0.0]]),
                      keys.SIMPLE_SCENE: torch.zeros(3, 1), keys.IS_STOP: torch.tensor([[False], [False], [True]]),
                      (keys.REWARD_TERMS, "local_occlusion"): torch.tensor([[0.0], [-7.0], [0.0]])}, batch_size=[3])
    assert r.reward(nxt).squeeze(-1).tolist() == [1.0, -1.0, -1.0]


def test_an_evaluation_reads_the_reward_at_the_end_of_the_beta_schedule():
    from mqa_rl.transforms.beta import BetaSchedule, trained_counter

    for reward in ({"beta_horizon": 2000, "beta_final": 0.5}, {"beta_horizon": 7.5, "beta_final": 0.2}):
        schedule = BetaSchedule(reward["beta_horizon"], trained_counter(reward), final=reward["beta_final"])
        assert schedule.beta == pytest.approx(reward["beta_final"])          # not 1: R_e alone
    assert BetaSchedule(2000, trained_counter({}), final=0.5).beta == pytest.approx(0.5)   # the configs' default T

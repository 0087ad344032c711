"""R_c, the countable-targets reward term: its formula on stored transitions, its checks and its configs."""

import math

import pytest
import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.transforms import CountableTargetsReward, make_reward_transform

PX = 20.0


def transition(visible_before, visible_after, targets, batch=()):
    k = len(targets)

    def info(visible):
        return {"visible_area": torch.tensor(visible, dtype=torch.float32), "target_mask": torch.tensor(targets),
                "object_mask": torch.ones(k, dtype=torch.bool), "overlap": torch.full((k,), 0.5),
                "object_pos": torch.zeros(k, 3), "question_type": torch.tensor([0]), "is_stop": torch.tensor([False])}

    return TensorDict({keys.INFO: info(visible_before), "next": {keys.INFO: info(visible_after)}}, batch_size=batch)


def test_made_countable_minus_buried_over_the_targets():
    # 4 targets: one rises to the line, one falls below it, one stays counted, one stays hidden; a non-target
    # rising does not count, and a NaN in a non-target slot is ignored
    td = transition([PX - 1, PX, 500.0, 0.0, 0.0, math.nan], [PX, PX - 0.5, 400.0, 3.0, 900.0, math.nan],
                    [True, True, True, True, False, False])
    assert CountableTargetsReward()(td)["next", *keys.COUNTABLE_TARGETS].item() == 0.0
    td = transition([0.0, 0.0, 30.0], [25.0, 40.0, 30.0], [True, True, True])
    assert CountableTargetsReward()(td)["next", *keys.COUNTABLE_TARGETS].item() == pytest.approx(2 / 3)
    assert CountableTargetsReward(normalise="none")(td)["next", *keys.COUNTABLE_TARGETS].item() == 2.0
    assert CountableTargetsReward(min_px=35.0)(td)["next", *keys.COUNTABLE_TARGETS].item() == pytest.approx(1 / 3)
    none = transition([0.0], [900.0], [False])                            # no target: nothing to count
    assert CountableTargetsReward()(none)["next", *keys.COUNTABLE_TARGETS].item() == 0.0


def test_bad_measurements_and_configs_are_named():
    with pytest.raises(ValueError, match=r"CountableTargetsReward: \(\"next\", \"info\", \"visible_area\"\) is NaN"):
        CountableTargetsReward()(transition([0.0], [math.nan], [True]))
    with pytest.raises(KeyError, match="CountableTargetsReward needs .*visible_area"):
        CountableTargetsReward()(transition([0.0], [1.0], [True]).exclude(keys.VISIBLE_AREA))
    for bad in (0, -5.0, float("nan"), "20", True):
        with pytest.raises(ValueError, match="min_px must be a finite number > 0"):
            CountableTargetsReward(min_px=bad)
    with pytest.raises(ValueError, match=r"normalise must be one of \['targets', 'none'\]"):
        CountableTargetsReward(normalise="area")
    with pytest.raises(ValueError, match="reward term 'countable_targets'.*it takes \\['min_px', 'normalise'\\]"):
        make_reward_transform({"terms": {"countable_targets": {"min_pixels": 20}}}, push_length=0.12)


def test_a_reward_config_recombines_it_with_the_papers_terms():
    cfg = {"terms": {"global_occlusion": {}, "countable_targets": {}},
           "question_weights": {"global_occlusion": 0.5, "countable_targets": 1.0}, "beta_final": 0.0, "beta_horizon": 1}
    stack = make_reward_transform(cfg, push_length=0.12, counter=torch.tensor(10))      # beta past its horizon: 0
    out = stack(transition([0.0, 30.0], [25.0, 30.0], [True, True]))["next"]
    assert out[keys.BETA].item() == 0.0
    expected = 0.5 * out[keys.GLOBAL_OCCLUSION].item() + 1.0 * 0.5
    assert out[keys.REWARD].item() == pytest.approx(expected)

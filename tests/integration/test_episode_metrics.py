"""What an evaluation reports per episode: the targets' χ and the targets crossing the counting line."""

import math

import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.envs import actions
from mqa_rl.evaluation.episode_metrics import episode_metrics
from mqa_rl.transforms.episode_stats import COUNTABLE_PX, targets_in_view
from mqa_rl.transforms.mqa_env import make_mqa_env

from conftest import REPO


def _final(target, visible_end, in_view_start, chi, question_type="counting"):
    return TensorDict({
        keys.QUESTION_TYPE: torch.tensor([QUESTION_TYPES.index(question_type)]),
        keys.TARGET_MASK: torch.tensor(target), keys.VISIBLE_AREA: torch.tensor(visible_end, dtype=torch.float32),
        keys.OVERLAP: torch.tensor(chi), keys.TARGETS_IN_VIEW_START: torch.tensor(in_view_start),
        keys.TARGET_CHI_START: torch.tensor([0.5]), keys.EPISODE_REWARD: torch.zeros(1),
        keys.PUSH_COUNT: torch.tensor([3]), keys.IS_STOP: torch.tensor([True]),
    }, batch_size=[]).unsqueeze(0)


def test_targets_crossing_the_counting_line_are_counted_both_ways():
    px = COUNTABLE_PX
    # four targets: one comes into view, one goes out of it, one stays in view, one stays hidden; one non-target
    final = _final(target=[True, True, True, True, False], visible_end=[px, px - 1, 500.0, 0.0, 900.0],
                   in_view_start=[False, True, True, False, False], chi=[0.5, 0.9, 0.1, 1.0, 0.0])
    m = episode_metrics(final)
    assert m["into_view"].item() == 0.25 and m["out_of_view"].item() == 0.25 and m["in_view_change"].item() == 0.0
    assert m["hidden_end"].item() == 0.25
    none = _final(target=[False, False], visible_end=[0.0, 50.0], in_view_start=[False, False], chi=[1.0, 0.0])
    assert math.isnan(episode_metrics(none)["into_view"].item())         # no target: nothing to count


def test_countable_gain_and_the_perfect_counter_on_each_frame():
    px = COUNTABLE_PX
    # three targets: one made countable, two buried (one of them was the only one countable with it at start)
    m = episode_metrics(_final(target=[True, True, True], visible_end=[px, 0.0, px - 1],
                               in_view_start=[False, True, True], chi=[0.5, 1.0, 0.9]))
    assert (m["countable_made"].item(), m["countable_buried"].item(), m["countable_gain"].item()) == (1.0, 2.0, -1.0)
    # the answer is 3: no single frame shows all three, the two frames together do
    assert (m["counter_start"].item(), m["counter_stop"].item(), m["counter_either"].item()) == (0.0, 0.0, 1.0)
    # all countable at the end: the counter on I_stop is right, a net gain of one
    m = episode_metrics(_final(target=[True, True, False], visible_end=[px, 400.0, 0.0], in_view_start=[False, True, False],
                               chi=[0.5, 0.1, 1.0]))
    assert m["countable_gain"].item() == 1.0 and (m["counter_start"].item(), m["counter_stop"].item()) == (0.0, 1.0)
    # an answer of 0 (no target) is read right from any frame; another question type has no count to read
    none = episode_metrics(_final(target=[False], visible_end=[50.0], in_view_start=[False], chi=[0.0]))
    assert none["counter_stop"].item() == 1.0 and none["countable_gain"].item() == 0.0
    logic = episode_metrics(_final(target=[True], visible_end=[50.0], in_view_start=[True], chi=[0.0], question_type="logic"))
    assert math.isnan(logic["counter_stop"].item()) and logic["countable_gain"].item() == 0.0


def test_the_env_records_which_targets_were_in_view_at_reset_and_keeps_it(small_dataset_dir):
    reward = OmegaConf.to_container(OmegaConf.load(REPO / "recipes" / "conf" / "reward" / "global.yaml"))
    env = make_mqa_env(small_dataset_dir, reward, episode_stats=True, split=None, seed=0, max_pushes=3)
    try:
        env.set_seed(3)
        for _ in range(4):                         # until a question with a target, pushed at twice
            td = env.reset()
            if td.get(keys.TARGET_MASK).any():
                break
        assert td.get(keys.TARGET_MASK).any()
        start = targets_in_view(td)
        assert start.any()                         # a target a counter sees (the small scenes are sparse)
        assert torch.equal(td.get(keys.TARGETS_IN_VIEW_START), start)
        mask = td.get(keys.ACTION_MASK)
        push = int(torch.nonzero(mask[: actions.STOP]).flatten()[0])
        for _ in range(2):
            td = env.step(td.set(keys.ACTION, torch.tensor(push)))["next"]
            assert torch.equal(td.get(keys.TARGETS_IN_VIEW_START), start)
        assert env.observation_spec[keys.TARGETS_IN_VIEW_START].is_in(td.get(keys.TARGETS_IN_VIEW_START))
    finally:
        env.close()


def test_scene_bootstrap_interval_widens_when_a_scene_decides_its_questions_together():
    import torch

    from mqa_rl.evaluation.episode_metrics import scene_bootstrap_ci95

    # 10 scenes of 20 questions: right or wrong by whole scene, vs the same 200 answers shuffled over scenes
    clustered = torch.tensor([1.0] * 100 + [0.0] * 100)
    scenes = torch.arange(10).repeat_interleave(20)
    mean, low, high, n = scene_bootstrap_ci95(clustered, scenes)
    assert mean == 0.5 and n == 10 and low < 0.3 and high > 0.7
    mixed = clustered[torch.randperm(200, generator=torch.Generator().manual_seed(0))]
    _, low_m, high_m, _ = scene_bootstrap_ci95(mixed, scenes)
    assert high_m - low_m < 0.6 * (high - low)

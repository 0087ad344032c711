"""The reward stack on the real env, in a replay buffer, and with β reaching collector workers."""


import pytest
import torch
import yaml
from torchrl.envs import TransformedEnv
from torchrl.envs.utils import check_env_specs

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.transforms import BetaSchedule, make_reward_transform
from mqa_rl.transforms.factory import register_term
from mqa_rl.transforms.base import RewardTerm
from mqa_rl.transforms.functional import countable_targets_reward, local_occlusion_reward
from mqa_rl.transforms.mqa_env import make_mqa_env
from conftest import REPO

CONF = REPO / "recipes" / "conf" / "reward"
VARIANTS = sorted(p.stem for p in CONF.glob("*.yaml"))
TERMS = ("exploration", "simple_scene", "beta")


def reward_cfg(name):
    return yaml.safe_load((CONF / f"{name}.yaml").read_text())


@pytest.fixture(scope="module")
def base(small_dataset):
    return SapienBinEnv(small_dataset, split=None, seed=0, max_pushes=4)


@pytest.fixture(scope="module")
def env(base):
    return TransformedEnv(base, make_reward_transform(reward_cfg("global_local"), push_length=base.push_length))


def _act(env, td, action):
    td = td.clone()
    td[keys.ACTION] = torch.tensor(action)
    return env.step(td)["next"]


def test_the_papers_variants_exist():
    assert {"global", "local", "global_local"} <= set(VARIANTS)


@pytest.mark.parametrize("variant", VARIANTS)
def test_specs_and_every_term_in_a_rollout(base, variant):
    env = TransformedEnv(base, make_reward_transform(reward_cfg(variant), push_length=base.push_length))
    check_env_specs(env, seed=0)
    r = env.rollout(3, break_when_any_done=False)
    names = set(reward_cfg(variant)["terms"]) | set(TERMS)
    for name in names:
        assert (keys.REWARD_TERMS, name) in r.keys(True) and ("next", keys.REWARD_TERMS, name) in r.keys(True)
    assert torch.isfinite(r["next", keys.REWARD]).all()


def test_the_countable_term_is_its_formula_on_the_envs_measurements(base):
    env = TransformedEnv(base, make_reward_transform(reward_cfg("countable"), push_length=base.push_length))
    r = env.rollout(4, break_when_any_done=False)
    expected = countable_targets_reward(r[keys.VISIBLE_AREA], r["next", *keys.VISIBLE_AREA], r[keys.TARGET_MASK], 20.0)
    assert torch.allclose(r["next", *keys.COUNTABLE_TARGETS].squeeze(-1), expected)


def _first(env, questions, want_simple):
    for q in questions:
        td = env.reset(question_id=q.id)
        tgt = td[keys.TARGET_MASK]
        simple = bool((~tgt | (td[keys.OVERLAP] <= 0.2)).all())
        if simple == want_simple and tgt.any():
            return td
    pytest.fail(f"no question with a {'simple' if want_simple else 'cluttered'} scene and a target")


def test_stop_in_simple_scene_plus_one_cluttered_minus_one(env, small_dataset):
    easy = [q for q in small_dataset.select(types="counting", difficulties="easy") if q.answer != "0"]
    td = _first(env, easy, want_simple=True)
    assert _act(env, td, actions.STOP)[keys.REWARD].item() == 1.0
    hard = [q for q in small_dataset.select(types="counting", difficulties="hard") if q.answer != "0"]
    td = _first(env, hard, want_simple=False)
    out = _act(env, td, actions.STOP)
    assert out[keys.REWARD].item() == -1.0 and out[keys.SIMPLE_SCENE].item() == 0.0
    empty = next(q for q in small_dataset.select(types="counting") if q.answer == "0")
    td = env.reset(question_id=empty.id)                      # no target: nothing to reveal → simple
    assert _act(env, td, actions.STOP)[keys.REWARD].item() == 1.0


def test_push_that_uncovers_a_target_gives_positive_local_reward(env, small_dataset):
    """Try the privileged oracle's candidate pushes on partly hidden targets until one reveals the
    most hidden one; R_l, and the reward mix, must then be exactly the formulas'."""
    from mqa_rl.modules.push.privileged_policy import PrivilegedPushPolicy

    oracle = PrivilegedPushPolicy(env.base_env)
    hard = [q for q in small_dataset.select(types="counting", difficulties="hard") if q.answer != "0"]
    for q in hard[:8]:
        td = env.reset(question_id=q.id)
        chi = td[keys.OVERLAP].clone()
        chi[~td[keys.TARGET_MASK]] = -1
        worst = int(chi.argmax())
        if not 0.2 < chi[worst] < 0.95:
            continue
        for action, _ in oracle.candidates(env.base_env.ground_truth())[:6]:
            td = env.reset(question_id=q.id)
            out = _act(env, td, action)
            expected = local_occlusion_reward(td[keys.OVERLAP], out[keys.OVERLAP], td[keys.TARGET_MASK])
            assert out[keys.LOCAL_OCCLUSION].item() == pytest.approx(expected.item())
            if out[keys.LOCAL_OCCLUSION].item() > 0:
                assert out[keys.OVERLAP][td[keys.TARGET_MASK]].max() < chi[worst]
                beta = out[keys.BETA]
                mix = beta * out[keys.EXPLORATION] + (1 - beta) * 0.5 * (out[keys.GLOBAL_OCCLUSION] + out[keys.LOCAL_OCCLUSION])
                assert out[keys.REWARD].item() == pytest.approx(mix.item())
                return
    pytest.fail("no push uncovered the most hidden target")


def test_replay_buffer_rescoring_with_another_variant(env, base):
    from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

    data = env.rollout(4, break_when_any_done=False)
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(16), batch_size=4,
                                transform=make_reward_transform(reward_cfg("local"), push_length=base.push_length))
    rb.extend(data)
    s = rb.sample()
    nxt = s["next"]
    expect = local_occlusion_reward(s[keys.OVERLAP], nxt[keys.OVERLAP], s[keys.TARGET_MASK])
    torch.testing.assert_close(nxt[keys.LOCAL_OCCLUSION].squeeze(-1), expect)
    push = ~nxt[keys.IS_STOP].squeeze(-1) & (nxt[keys.SIMPLE_SCENE].squeeze(-1) == 0)
    r = nxt[keys.BETA] * nxt[keys.EXPLORATION] + (1 - nxt[keys.BETA]) * nxt[keys.LOCAL_OCCLUSION]
    torch.testing.assert_close(nxt[keys.REWARD][push], r[push])


def test_beta_state_dict_resumes_the_schedule():
    a = BetaSchedule(2000)
    a.set_train_steps(1000)
    assert a.beta == pytest.approx(0.75)
    shared = torch.zeros((), dtype=torch.int64).share_memory_()
    b = BetaSchedule(2000, shared)
    b.load_state_dict(a.state_dict())
    assert b.beta == pytest.approx(0.75) and shared.item() == 1000    # loaded in place: still shared


def test_factory_rejects_bad_configs_and_accepts_new_terms(base):
    with pytest.raises(ValueError, match="unknown reward term"):
        make_reward_transform({"terms": {"curiosity": {}}}, push_length=0.1)
    with pytest.raises(ValueError, match="not in 'terms'"):
        make_reward_transform({"terms": {}, "question_weights": {"local_occlusion": 1}}, push_length=0.1)
    with pytest.raises(ValueError, match="unknown reward config keys"):
        make_reward_transform({"gamma": 0.9}, push_length=0.1)

    class TargetsVisible(RewardTerm):
        out_key = (keys.REWARD_TERMS, "targets_visible")

        def compute(self, before, after):
            t = after[keys.TARGET_MASK]
            return ((after[keys.OVERLAP] < 1) & t).sum(-1).float() / t.sum(-1).clamp(min=1)

    register_term("targets_visible", TargetsVisible)
    env = TransformedEnv(base, make_reward_transform(
        {"terms": {"targets_visible": {}}, "question_weights": {"targets_visible": 1.0}}, push_length=base.push_length))
    r = env.rollout(2, break_when_any_done=False)
    assert ("next", keys.REWARD_TERMS, "targets_visible") in r.keys(True)


@pytest.mark.timeout(300)
def test_beta_counter_reaches_collector_workers(small_dataset_dir):
    from torchrl.collectors import MultiSyncCollector

    from mqa_rl.modules.push.random_policy import RandomMQAPolicy

    counter = torch.zeros((), dtype=torch.int64).share_memory_()
    kwargs = {"dataset": str(small_dataset_dir), "reward": reward_cfg("local"), "counter": counter,
              "split": None, "max_pushes": 3}
    coll = MultiSyncCollector([make_mqa_env] * 2, RandomMQAPolicy(3), frames_per_batch=4, total_frames=12,
                              create_env_kwargs=[kwargs] * 2, auto_register_policy_transforms=False)
    betas = []
    try:
        for i, data in enumerate(coll):
            betas.append(data["next", keys.BETA].unique().tolist())
            counter.fill_(1000 * (i + 1))           # the trainer advances S_n (T = 2000)
    finally:
        coll.shutdown()
    assert betas == [[1.0], [0.75], [0.5]]


def test_scene_occlusion_can_take_the_place_of_exploration(base):
    """explore_term=scene_occlusion: β weighs R_s (R_g over every object) instead of R_e; R_s is the
    formula on all real objects, and an unknown explore term is refused."""
    from mqa_rl.transforms.functional import global_occlusion_reward

    cfg = {**reward_cfg("global"), "explore_term": "scene_occlusion", "reward_clip": None}
    env = TransformedEnv(base, make_reward_transform(cfg, push_length=base.push_length))
    td = env.reset()
    allowed = td[keys.ACTION_MASK][: actions.NUM_PUSHES].nonzero().squeeze(-1)
    for a in allowed[:: max(1, len(allowed) // 4)][:4]:
        out = env.step(td.clone().set(keys.ACTION, a))["next"]
        expect = global_occlusion_reward(td[keys.OVERLAP], out[keys.OVERLAP], td[keys.OBJECT_MASK])
        assert out[keys.SCENE_OCCLUSION].item() == pytest.approx(expect.item())
        if out[keys.SIMPLE_SCENE].item() == 0:
            beta = out[keys.BETA]
            assert out[keys.REWARD].item() == pytest.approx(
                (beta * out[keys.SCENE_OCCLUSION] + (1 - beta) * out[keys.GLOBAL_OCCLUSION]).item())
        td = out
    with pytest.raises(ValueError, match="explore_term"):
        make_reward_transform({**cfg, "explore_term": "curiosity"}, push_length=0.1)

"""The learned stop: optimal stopping by regression on a policy's own paths, its features, the stop
rule on a real Q-network actor, and its file."""

import warnings

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import Categorical

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.modules.stop.learned_stop import FEATURES, LearnedStop, StopCritic, policy_fingerprint, stop_features
from mqa_rl.modules.answering.kept_frame import FrameKeeper
from mqa_rl.modules.answering.perceived_count import READING, PerceivedCount, file_sha256, reading_env_kwargs
from mqa_rl.modules.answering.perception import CountingPerception, save_perception
from mqa_rl.modules.answering.vote_counting import MAX_COUNT
from mqa_rl.modules.push.push_policy import make_q_actor
from mqa_rl.modules.push.push_qnet import PushQNet
from mqa_rl.training.optimal_stopping import fit_stop_critic, fixed_rules, realised_values, stopped_chi
from torch_threads import one_torch_thread  # noqa: F401  (autouse)

VOCAB, S = 30, 224
from conftest import REPO as ROOT


def test_realised_values_follow_the_rule_along_each_path():
    chi = torch.tensor([[0.5, 0.3, 0.4], [0.6, 0.6, 0.6]])
    valid = torch.tensor([[True, True], [True, False]])          # the second episode ended after one push
    never = torch.zeros(2, 2, dtype=torch.bool)
    assert realised_values(chi, never, valid)[:, 0].tolist() == pytest.approx([0.4, 0.6])
    at_one = torch.tensor([[False, True], [False, True]])
    assert stopped_chi(chi, at_one, valid).tolist() == pytest.approx([0.3, 0.6])
    rules = fixed_rules(chi, valid)
    assert rules["after_0"] == pytest.approx(0.55) and rules["after_1"] == pytest.approx(0.45)
    assert rules["after_2"] == pytest.approx(0.5) and rules["hindsight"] == pytest.approx(0.45)


def test_the_fit_learns_to_push_on_where_pushing_uncovers_and_to_stop_where_it_covers():
    """Two kinds of scene told apart by one feature: in one each push lowers χ, in the other it raises it;
    the best rule pushes to the end in the first and stops at once in the second (hindsight optimum)."""
    g = torch.Generator().manual_seed(0)
    episodes, steps = 200, 5
    kind = torch.rand(episodes, generator=g) < 0.5
    slope = torch.where(kind, -0.08, 0.08)[:, None]
    chi = 0.5 + slope * torch.arange(steps + 1) + 0.01 * torch.randn(episodes, steps + 1, generator=g)
    features = torch.randn(episodes, steps, len(FEATURES), generator=g)
    features[..., 0] = kind[:, None].float() + 0.05 * torch.randn(episodes, steps, generator=g)
    valid = torch.ones(episodes, steps, dtype=torch.bool)
    critic, history = fit_stop_critic(features, chi, valid, steps=400, iterations=2)
    with torch.no_grad():
        stop = critic(features) >= 0
    assert stop[~kind, 0].float().mean() > 0.95 and (~stop[kind]).float().mean() > 0.95
    learned = stopped_chi(chi, stop, valid).mean()
    assert learned < min(fixed_rules(chi, valid)[f"after_{k}"] for k in range(steps + 1)) - 0.1
    assert history[-1]["chi_end"] == pytest.approx(float(learned), abs=1e-6)


def test_the_fit_refuses_paths_without_targets():
    chi = torch.full((3, 3), float("nan"))
    with pytest.raises(ValueError, match="without targets"):
        fit_stop_critic(torch.zeros(3, 2, len(FEATURES)), chi, torch.ones(3, 2, dtype=torch.bool))


def _actor(seed=0):
    torch.manual_seed(seed)
    net = PushQNet(VOCAB, camera_distance=0.9, class_map=True, num_classes=5, light_channels=(8, 8, 16, 16),
                   light_downsample=2, fuse_channels=(16, 8), head_channels=(8, 8), head_context=1, rotated_head=True,
                   geometric_push=True).eval()
    return make_q_actor(net, Categorical(actions.NUM_ACTIONS), masked=True), net


def _state(batch=2, masked=()):
    g = torch.Generator().manual_seed(1)
    mask = torch.ones(batch, actions.NUM_ACTIONS, dtype=torch.bool)
    mask[:, list(masked)] = False
    return TensorDict({keys.RGB: torch.randint(0, 256, (batch, 3, S, S), dtype=torch.uint8, generator=g),
                       keys.DEPTH: 0.8 + 0.1 * torch.rand(batch, 1, S, S, generator=g),
                       keys.QUESTION: torch.randint(1, VOCAB, (batch, 6), generator=g),
                       keys.ACTION_MASK: mask, keys.PUSH_COUNT: torch.tensor([[0], [3]])}, batch_size=[batch])


def _constant_critic(value: float) -> StopCritic:
    critic = StopCritic()
    for p in critic.parameters():
        torch.nn.init.zeros_(p)
    critic.mlp[-1].bias.data.fill_(value)
    return critic


def test_features_read_the_policys_values_and_the_geometry():
    actor, net = _actor()
    td = actor(_state())
    f = stop_features(net, td, max_pushes=10)
    assert f.shape == (2, len(FEATURES)) and torch.isfinite(f).all()
    q = td[keys.ACTION_VALUE]
    torch.testing.assert_close(f[:, 0], q[:, actions.STOP] - q[:, : actions.STOP].max(-1).values)
    assert f[:, FEATURES.index("pushes_done")].tolist() == pytest.approx([0.0, 0.3])
    maps = net.geometry_maps(td[keys.RGB], td[keys.DEPTH], td[keys.QUESTION])
    torch.testing.assert_close(f[:, FEATURES.index("target_mean")], maps[:, 0].mean((-2, -1)))


def test_the_policy_pushes_its_best_allowed_push_while_the_critic_predicts_a_gain_then_stops():
    actor, _ = _actor()
    plain = actor(_state())
    best = int(plain[keys.ACTION_VALUE][0, : actions.STOP].argmax())
    td = LearnedStop(actor, _constant_critic(-0.1), max_pushes=10)(_state(masked=[best]))
    assert (td[keys.ACTION] != actions.STOP).all() and (td[keys.ACTION] != best).all()   # an allowed push
    assert td[keys.ACTION_MASK].gather(-1, td[keys.ACTION][:, None]).all()
    q = td[keys.ACTION_VALUE]
    torch.testing.assert_close(td[keys.CHOSEN_ACTION_VALUE].flatten(), q.gather(-1, td[keys.ACTION][:, None]).flatten())
    td = LearnedStop(actor, _constant_critic(0.1), max_pushes=10)(_state())
    assert (td[keys.ACTION] == actions.STOP).all()
    td = LearnedStop(actor, _constant_critic(-0.1), max_pushes=10)(_state(masked=range(actions.NUM_PUSHES)))
    assert (td[keys.ACTION] == actions.STOP).all()                  # nothing allowed to push: it stops


def test_a_policy_without_a_target_map_is_refused():
    net = PushQNet(VOCAB, camera_distance=0.9, light_channels=(8, 8, 16, 16), light_downsample=2, fuse_channels=(16, 8),
                   head_channels=(8,))
    with pytest.raises(ValueError, match="class_map"):
        LearnedStop(make_q_actor(net, Categorical(actions.NUM_ACTIONS)), _constant_critic(0.0), max_pushes=10)


def test_the_critic_file_round_trips_and_bad_files_are_refused(tmp_path):
    actor, net = _actor()
    critic = _constant_critic(-0.2)
    critic.standardise_by(torch.randn(50, len(FEATURES)))
    path = critic.save(tmp_path / "stop" / "stop_critic.pt", {"policy_fingerprint": policy_fingerprint(net)})
    loaded, meta = StopCritic.load(tmp_path / "stop")                  # the folder finds its stop_critic.pt
    x = torch.randn(4, len(FEATURES))
    torch.testing.assert_close(loaded(x), critic(x))
    assert isinstance(LearnedStop.from_file(actor, path, 10), LearnedStop)
    other, _ = _actor(seed=1)
    with pytest.raises(ValueError, match="another policy"):
        LearnedStop.from_file(other, path, 10)
    with pytest.raises(FileNotFoundError, match="no stop-critic file"):
        StopCritic.load(tmp_path / "nowhere")
    (tmp_path / "cut.pt").write_bytes(path.read_bytes()[:200])
    with pytest.raises(ValueError, match="truncated"):
        StopCritic.load(tmp_path / "cut.pt")
    torch.save({"format": "something else"}, tmp_path / "foreign.pt")
    with pytest.raises(ValueError, match="not a stop-critic file"):
        StopCritic.load(tmp_path / "foreign.pt")
    assert not list((tmp_path / "stop").glob(".*tmp*"))                # nothing half-written left behind


def test_a_critic_fitted_under_another_push_memory_warns(tmp_path):
    """The critic predicts what the policy's next pushes gain; with another memory it makes other pushes."""
    actor, net = _actor()
    path = _constant_critic(-0.2).save(tmp_path / "stop_critic.pt",
                                       {"policy_fingerprint": policy_fingerprint(net), "push_memory": 1})
    with pytest.warns(UserWarning, match="push_memory=1 and runs with push_memory=None"):
        LearnedStop.from_file(actor, path, 10)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        LearnedStop.from_file(actor, path, 10, push_memory=1)
        old = _constant_critic(-0.2).save(tmp_path / "old.pt", {"policy_fingerprint": policy_fingerprint(net)})
        LearnedStop.from_file(actor, old, 10, push_memory=1)     # written before the fit recorded its memory


def test_the_shipped_critic_loads_and_names_its_policy():
    critic, meta = StopCritic.load(ROOT / "checkpoints" / "stop_geometric_student")
    assert meta["run"] == "checkpoints/dqn_geometric_student" and len(meta["policy_fingerprint"]) == 64
    assert critic(torch.zeros(3, len(FEATURES))).shape == (3,)


def test_the_shipped_countable_critic_minimises_what_the_counter_misses():
    critic, meta = StopCritic.load(ROOT / "checkpoints" / "stop_countable")
    assert meta["value"] == "uncountable" and meta["run"] == "runs/countable_rl/countable/dqn"
    assert critic(torch.zeros(2, len(FEATURES))).shape == (2,)


def _reading(tmp_path, classes=4):
    """A tiny counting perception on file and the PerceivedCount over it (token t names class channel t here)."""
    torch.manual_seed(0)
    path = save_perception(CountingPerception(1 + classes, widths=(8, 8, 16, 16)), tmp_path / "perception.pt", {})
    table = torch.zeros(VOCAB, dtype=torch.int64)
    table[1:1 + classes] = torch.arange(1, 1 + classes)
    return PerceivedCount.from_file(path, table), path


def test_the_perceived_count_reads_the_asked_class_on_the_finest_frame_it_is_given(tmp_path):
    reading, _ = _reading(tmp_path)
    size = reading.input_size
    g = torch.Generator().manual_seed(2)
    frames = torch.randint(0, 256, (2, 3, size, size), dtype=torch.uint8, generator=g)
    question = torch.tensor([[9, 9, 3, 9], [9, 2, 4, 9]])                       # asks class 3, then class 2
    out = reading(frames, question)
    assert out.shape == (2, len(READING)) and torch.isfinite(out).all()
    counts = reading.perception.counts(frames)                                  # [B, classes]
    assert out[:, 0].tolist() == [float(min(counts[0, 2], MAX_COUNT)), float(min(counts[1, 1], MAX_COUNT))]
    td = TensorDict({keys.RGB: frames[:, :, ::2, ::2], keys.ANSWER_RGB: frames, keys.QUESTION: question}, batch_size=[2])
    torch.testing.assert_close(reading.read(td), out)                          # the answer camera, not the coarser rgb
    with pytest.raises(ValueError, match="answer_observation=true"):
        reading.read(td.exclude(keys.ANSWER_RGB))
    with pytest.raises(ValueError, match="names no class"):
        reading(frames, torch.tensor([[9, 9, 9, 9], [9, 2, 9, 9]]))


def test_a_critic_reading_the_perception_round_trips_and_refuses_another_perception_file(tmp_path):
    actor, net = _actor()
    reading, path = _reading(tmp_path)
    width = len(FEATURES) + len(READING)
    critic = StopCritic(width)
    critic.reading = reading
    assert critic.reading_source["sha256"] == file_sha256(path)
    saved = critic.save(tmp_path / "stop" / "stop_critic.pt", {"policy_fingerprint": policy_fingerprint(net)})
    loaded, _ = StopCritic.load(saved)
    assert loaded.feature_names == [*FEATURES, *READING] and loaded.reading is not None
    x = torch.randn(3, width)
    torch.testing.assert_close(loaded(x), critic(x))
    size = reading.input_size
    td = _state()
    td.set(keys.ANSWER_RGB, torch.randint(0, 256, (2, 3, size, size), dtype=torch.uint8))
    td.set(keys.QUESTION, torch.tensor([[1, 5, 9, 9, 9, 9], [2, 9, 9, 9, 9, 9]]))
    stop = LearnedStop.from_file(actor, saved, 10)
    out = stop(td.clone())
    features = loaded.read(net, actor(td.clone()), 10)
    assert features.shape == (2, width)
    torch.testing.assert_close(features[:, len(FEATURES):], reading.read(td))
    assert out[keys.ACTION].shape == (2,)
    torch.testing.assert_close(out[keys.PERCEIVED_READING], reading.read(td))     # left in the state for a keeper
    keeper, own = FrameKeeper(reading, stop), FrameKeeper(reading)
    assert keeper.reuse and not own.reuse
    episode = td.clone()
    episode.set(keys.QUESTION, td[keys.QUESTION][:1].expand(2, -1).clone())     # an episode asks one question
    out = stop(episode)
    states = [s.exclude(keys.PERCEIVED_READING) if i == 2 else s for i, s in enumerate([*out.unbind(0), out[0]])]
    assert keeper.choose(states) == own.choose(states)                            # the same frame, fewer readings
    keeper.reading = None                                                         # the reused ones need no perception
    with pytest.raises(AttributeError):
        keeper.choose(states)                                                     # ... but the last state's does
    assert keeper.choose(states[:2]) == own.choose(states[:2])
    assert reading_env_kwargs(loaded.reading, image_size=size // 2) == {"answer_size": size, "answer_observation": True}
    assert reading_env_kwargs(loaded.reading, image_size=size) == {} and reading_env_kwargs(None, 224) == {}
    save_perception(CountingPerception(5, widths=(8, 8, 16, 16)), path, {})   # another perception at that path
    with pytest.raises(ValueError, match="SHA-256 differs"):
        StopCritic.load(saved)
    assert not FrameKeeper(PerceivedCount.from_file(path, reading.token_channel), stop).reuse   # another file: read anew


def test_the_shipped_perceiving_critic_reads_the_shipped_perception_on_the_answer_camera():
    critic, meta = StopCritic.load(ROOT / "checkpoints" / "stop_countable_perceived")
    assert meta["value"] == "uncountable" and meta["run"] == "checkpoints/dqn_countable"
    assert critic.feature_names == [*FEATURES, *READING] and critic.reading.input_size == 448
    assert critic.reading_source["perception"] == "checkpoints/vqa_counting/perception.pt"
    assert reading_env_kwargs(critic.reading, 224) == {"answer_size": 448, "answer_observation": True}
    assert critic(torch.zeros(2, len(FEATURES) + len(READING))).shape == (2,)

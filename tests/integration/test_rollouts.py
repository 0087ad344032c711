"""Rollouts of frozen policies for the VQA: what a record holds, the store's round trip, resuming an
interrupted collection without duplicates, worker processes, the DQN-checkpoint path and the
references (no manipulation, privileged)."""

import json

import pytest
import torch
from tensordict import TensorDict
from omegaconf import OmegaConf

from mqa_rl import keys
from mqa_rl.collectors import rollouts
from mqa_rl.collectors.rollouts import collect_rollouts, plan_questions
from mqa_rl.collectors.store import EpisodeStore, StoreError, load_records
from mqa_rl.data.dataset import LEVELS
from mqa_rl.modules.frozen_policies import resolve_checkpoint
from mqa_rl.modules.systems import system_spec
from conftest import REPO, system_registry

PLAN = dict(policy={"kind": "random"}, split="train", question_types=["counting"], max_per_group=1, repeats=2,
            max_pushes=2, workers=1, chunk_episodes=2, progress=False)


@pytest.fixture(scope="module")
def random_store(small_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("rollouts") / "random"
    summary = collect_rollouts(out, dataset=small_dataset, **PLAN)
    return out, summary


def test_records_hold_the_episode(small_dataset, random_store):
    out, summary = random_store
    questions = plan_questions(small_dataset, "train", ["counting"], max_per_group=1)
    assert summary["episodes"] == 2 * len(questions) == summary["collected_now"]
    r = load_records(out)
    assert r.shape == (2 * len(questions),) and r[keys.SLOT].tolist() == list(range(r.shape[0]))
    assert r[keys.REPEAT].tolist() == [0, 1] * len(questions)
    assert r[keys.QUESTION_ID].tolist() == [q for q in questions for _ in range(2)]
    assert r[keys.FIRST_RGB].dtype == torch.uint8 and r[keys.FIRST_RGB].shape[1:] == (3, 224, 224)
    assert r[keys.LAST_DEPTH].dtype == torch.float16 and r[(keys.LAST, keys.OBJECT_MAP)].dtype == torch.uint8
    assert ((r[keys.PUSHES] >= 0) & (r[keys.PUSHES] <= 2)).all()
    for i in range(r.shape[0]):
        q = small_dataset.questions[int(r[keys.QUESTION_ID][i])]
        scene = small_dataset.scenes[int(r[keys.SCENE][i])]
        assert q.scene_id == scene.id and LEVELS[int(r[keys.LEVEL][i])] == scene.difficulty
        assert small_dataset.answers[int(r[keys.ANSWER_LABEL][i])] == q.answer
        assert small_dataset.vocab.decode(r[keys.QUESTION][i]) == small_dataset.vocab.decode(q.tokens)
        # the object map is the segmentation: each object's pixels = its visible area A_s
        for frame in (keys.FIRST, keys.LAST):
            omap, visible = r[(frame, keys.OBJECT_MAP)][i], r[(frame, keys.FRAME_VISIBLE)][i]
            counts = torch.bincount(omap.flatten().long(), minlength=len(scene.objects) + 1)[1:]
            assert torch.equal(counts.float(), visible[: len(scene.objects)]), frame
        # the targets' mean χ of the first image
        t = r[keys.EPISODE_TARGETS][i]
        chi = r[(keys.FIRST, keys.FRAME_OVERLAP)][i][t].mean() if t.any() else torch.tensor(float("nan"))
        assert torch.allclose(r[keys.CHI_START][i], chi, equal_nan=True)
    # repeats of a question start from the same image (the same settled scene)
    assert torch.equal(r[keys.FIRST_RGB][0], r[keys.FIRST_RGB][1])
    assert json.loads((out / "collect_log.jsonl").read_text().splitlines()[-1])["episodes"] == r.shape[0]


def test_interrupted_collection_resumes_without_duplicates(small_dataset, random_store, tmp_path, monkeypatch):
    reference = load_records(random_store[0])
    out = tmp_path / "resumed"
    real, calls = rollouts.run_question_episode, []

    def flaky(*args, **kwargs):
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt               # Ctrl-C in the middle of the 4th episode
        return real(*args, **kwargs)

    monkeypatch.setattr(rollouts, "run_question_episode", flaky)
    with pytest.raises(KeyboardInterrupt):
        collect_rollouts(out, dataset=small_dataset, **{**PLAN, "chunk_episodes": 2})
    monkeypatch.setattr(rollouts, "run_question_episode", real)
    assert load_records(out, require_complete=False).shape[0] == 3      # finished episodes were kept
    with pytest.raises(StoreError, match="interrupted"):
        load_records(out)
    (out / ".chunk-00009.tmp-1").mkdir()                                  # a killed writer's partial chunk
    summary = collect_rollouts(out, dataset=small_dataset, **PLAN)
    assert summary["already_there"] == 3 and summary["collected_now"] == reference.shape[0] - 3
    assert not list(out.glob(".chunk-*"))
    resumed = load_records(out)
    assert resumed[keys.SLOT].tolist() == reference[keys.SLOT].tolist()  # nothing duplicated or lost
    for key in (keys.LAST_RGB, keys.PUSHES, keys.CHI_END):                # slot-seeded: the same episodes
        assert torch.equal(resumed[key], reference[key]), key
    assert collect_rollouts(out, dataset=small_dataset, **PLAN)["collected_now"] == 0


def test_store_refuses_another_plan_and_a_second_writer(small_dataset, random_store, tmp_path):
    out, _ = random_store
    with pytest.raises(StoreError, match="another collection.*overwrite"):
        collect_rollouts(out, dataset=small_dataset, **{**PLAN, "repeats": 3})
    meta = {"slots": 1, "x": 1}
    with EpisodeStore(tmp_path / "s", meta):
        with pytest.raises(StoreError, match="another process"):
            EpisodeStore(tmp_path / "s", meta)
    # a collection that stored nothing (its policy failed to load) does not block the corrected command
    with EpisodeStore(tmp_path / "s", {"slots": 1, "x": 2}) as store:
        assert json.loads((tmp_path / "s" / "meta.json").read_text())["x"] == 2
        store.append(TensorDict({keys.SLOT: torch.tensor([0])}, batch_size=[1]))
    with pytest.raises(StoreError, match="another collection"):                # once it holds episodes it does
        EpisodeStore(tmp_path / "s", {"slots": 1, "x": 3})


def test_worker_processes_give_the_same_episodes(small_dataset, small_dataset_dir, random_store, tmp_path, monkeypatch):
    monkeypatch.setattr(rollouts, "IN_PROCESS_BELOW", 0)
    out = tmp_path / "pool"
    summary = collect_rollouts(out, dataset=small_dataset_dir, **{**PLAN, "workers": 2})
    assert summary["workers"] == 2
    pooled, reference = load_records(out), load_records(random_store[0])
    for key in (keys.SLOT, keys.LAST_RGB, keys.PUSHES):
        assert torch.equal(pooled[key], reference[key]), key


def _fake_dqn_run(run, env):
    """A train_dqn.py output folder with an untrained light Q-network checkpoint."""
    from torchrl.checkpoint import Checkpoint, CheckpointRotation

    from mqa_rl.modules.push.push_policy import make_push_qnet, make_q_actor
    from mqa_rl.verified_checkpoint import INTEGRITY, IntegrityAdapter

    model = OmegaConf.load(REPO / "recipes" / "conf" / "trunk" / "light.yaml")
    cfg = OmegaConf.create({"model": model, "action_mask": True})
    run.mkdir(parents=True)
    OmegaConf.save(cfg, run / "config.yaml")
    net = make_push_qnet(cfg.model, vocab_size=len(env.dataset.vocab), camera_distance=env.camera.distance)
    actor = make_q_actor(net, env.action_spec)
    ckpt = Checkpoint(policy=actor)
    ckpt.register(INTEGRITY, {}, adapter=IntegrityAdapter())          # load_greedy checks the files' SHA-256
    CheckpointRotation(run / "checkpoints", keep_last=1).save(ckpt, step=5)


def test_dqn_checkpoint_and_reference_policies(small_dataset, tmp_path):
    from mqa_rl.envs.sapien_bin import SapienBinEnv

    run = tmp_path / "dqn_run"
    with pytest.raises(FileNotFoundError, match="train the policy first"):
        resolve_checkpoint({"kind": "dqn", "run": str(run)})
    _fake_dqn_run(run, SapienBinEnv(small_dataset, split="train"))
    plan = {**PLAN, "max_per_group": 2, "split": "test", "chunk_episodes": 8}
    levels = ["hard"]
    out = tmp_path / "dqn"
    summary = collect_rollouts(out, dataset=small_dataset, levels=levels, **{**plan, "policy": {"kind": "dqn", "run": str(run)}})
    meta = json.loads((out / "meta.json").read_text())
    assert meta["policy"]["checkpoint"].endswith("checkpoint-000000000005")     # the weights used are recorded
    assert meta["plan"]["repeats"] == 1 and summary["episodes"] == 2                 # deterministic: one per question
    r = load_records(out)
    assert (r[keys.PUSHES] == 2).all() or r[keys.STOPPED].any()                 # greedy episodes ran to an end
    out = tmp_path / "none"
    collect_rollouts(out, dataset=small_dataset, levels=levels, **{**plan, "policy": {"kind": "none"}})
    r = load_records(out)
    assert (r[keys.PUSHES] == 0).all() and r[keys.STOPPED].all() and torch.equal(r[keys.FIRST_RGB], r[keys.LAST_RGB])
    out = tmp_path / "privileged"
    collect_rollouts(out, dataset=small_dataset, levels=levels, **{**plan, "policy": {"kind": "privileged", "lookahead": 1}})
    r = load_records(out)
    assert r.shape[0] == 2 and (r[keys.PUSHES] <= 2).all()


def test_a_run_trained_with_push_memory_is_rolled_out_with_it(small_dataset, small_dataset_dir, tmp_path):
    """A policy trained and stop-fitted with the push memory (env.push_memory in its run's config) runs in the
    answering rollouts with it: no push twice in an episode; push_memory=-1 turns it off."""
    from torchrl.envs import TransformedEnv
    from torchrl.envs.utils import set_exploration_type

    from mqa_rl.envs import actions
    from mqa_rl.envs.sapien_bin import SapienBinEnv

    run = tmp_path / "dqn_run"
    _fake_dqn_run(run, SapienBinEnv(small_dataset, split="train"))
    cfg = OmegaConf.load(run / "config.yaml")
    cfg.env = {"push_memory": 1}
    OmegaConf.save(cfg, run / "config.yaml")
    never_stop = {"kind": "dqn", "run": str(run), "stop_margin": 1e9}
    assert "push_memory" not in resolve_checkpoint({**never_stop, "push_memory": -1})
    spec = resolve_checkpoint(never_stop)
    assert spec["push_memory"] == 1
    env_kwargs = {"max_pushes": 4, "image_size": 224, "pusher": "finger"}
    state = rollouts._build(str(small_dataset_dir), env_kwargs, spec, {})
    env = state["env"]
    assert isinstance(env, TransformedEnv)
    question = next(q for q in small_dataset.questions if small_dataset.scene(q.scene_id).difficulty == "hard")
    td = env.reset(question_id=question.id)
    with torch.no_grad(), set_exploration_type(state["exploration"]):
        traj = env.rollout(5, state["policy"], auto_reset=False, tensordict=td, break_when_any_done=True)
    taken = traj[keys.ACTION].reshape(-1).tolist()
    assert len(taken) == 4 and actions.STOP not in taken
    assert len(set(taken)) == 4                                  # the memory masked every earlier push
    for t in range(1, 4):
        assert not traj[keys.ACTION_MASK][t, taken[:t]].any()
    env.close()


def test_the_answer_camera_stores_finer_frames_of_the_same_view_and_a_finer_vqa_takes_them(small_dataset, random_store,
                                                                                             tmp_path):
    """``answer_size``: I_start / I_stop through a second camera at 448 px beside the env's 224-px frames (the push
    grid stays at 224); the answer frames are the same view (their 2 × 2 means ≈ the env's render); a VQA reading
    448-px frames takes them, one reading 224 px the env's, and a finer VQA than a store holds is refused; a collection
    asking for no answer camera resumes the store as it is."""
    from mqa_rl.training.vqa_data import ANSWER_IMAGE_KEYS, IMAGE_KEYS, frame_keys, load_answering_records
    out = tmp_path / "answer448"
    collect_rollouts(out, dataset=small_dataset, **{**PLAN, "policy": {"kind": "none"}, "answer_size": 448,
                                                    "store_depth": False})
    r = load_records(out)
    assert json.loads((out / "meta.json").read_text())["env"]["answer_size"] == 448
    for frame in (keys.FIRST, keys.LAST):
        fine, env_rgb = r[(frame, keys.ANSWER_RGB)], r[(frame, keys.RGB)]
        assert fine.dtype == torch.uint8 and fine.shape[1:] == (3, 448, 448) and env_rgb.shape[1:] == (3, 224, 224)
        pooled = torch.nn.functional.avg_pool2d(fine.float(), 2)
        assert (pooled - env_rgb.float()).abs().mean() < 3.0, frame
    assert frame_keys(out, 448) == ANSWER_IMAGE_KEYS
    assert frame_keys(out, 224) == IMAGE_KEYS and frame_keys(out, None) == IMAGE_KEYS
    assert load_answering_records(out, size=448)[keys.FIRST_RGB].shape[-1] == 448
    assert torch.equal(load_answering_records(out, size=224)[keys.FIRST_RGB], r[keys.FIRST_RGB])
    for store, size in ((out, 896), (random_store[0], 448)):
        with pytest.raises(ValueError, match=f"collection.env.answer_size={size}"):
            frame_keys(store, size)
    # a collection for a VQA reading the env's frames (vqa=eqa) takes this store as it is, not as another plan
    again = collect_rollouts(out, dataset=small_dataset, **{**PLAN, "policy": {"kind": "none"}, "store_depth": False})
    assert again["collected_now"] == 0 and json.loads((out / "meta.json").read_text())["env"]["answer_size"] == 448


@pytest.mark.parametrize("size", [300, 112, True, 448.5])
def test_an_answer_size_off_the_env_grid_is_refused(small_dataset, size):
    from mqa_rl.envs.sapien_bin import SapienBinEnv
    with pytest.raises(ValueError, match="answer_size must be a multiple of image_size"):
        SapienBinEnv(small_dataset, split=None, answer_size=size)


def test_the_answer_observation_puts_the_answer_cameras_frame_in_every_state(small_dataset):
    """``answer_observation``: what a stop reading the counting perception acts on (the frame the VQA reads), in
    the spec, at reset and after a push and a stop; refused without an answer camera."""
    from mqa_rl.envs import actions
    from mqa_rl.envs.sapien_bin import SapienBinEnv
    with pytest.raises(ValueError, match="give answer_size"):
        SapienBinEnv(small_dataset, split=None, answer_observation=True)
    env = SapienBinEnv(small_dataset, split=None, answer_size=448, answer_observation=True, max_pushes=2)
    try:
        assert env.observation_spec[keys.ANSWER_RGB].shape == (3, 448, 448)
        td = env.reset(question_id=small_dataset.questions[0].id)
        assert torch.equal(td[keys.ANSWER_RGB], env.answer_image())
        td = env.step(td.set(keys.ACTION, torch.tensor(int(td[keys.ACTION_MASK][:actions.STOP].nonzero()[0]))))["next"]
        assert td[keys.ANSWER_RGB].shape == (3, 448, 448) and torch.equal(td[keys.ANSWER_RGB], env.answer_image())
        stopped = env.step(td.set(keys.ACTION, torch.tensor(actions.STOP)))["next"]
        assert torch.equal(stopped[keys.ANSWER_RGB], td[keys.ANSWER_RGB])
    finally:
        env.close()
    plain = SapienBinEnv(small_dataset, split=None, answer_size=448)
    try:
        assert keys.ANSWER_RGB not in plain.reset(question_id=small_dataset.questions[0].id).keys()
    finally:
        plain.close()


def test_each_asked_class_has_a_token_that_names_it(small_dataset):
    """The perceived count finds the asked class from the question's tokens alone (``token_channels``)."""
    from mqa_rl.modules.answering.perceived_count import PerceivedCount, token_channels
    from mqa_rl.modules.answering.perception import CountingPerception
    table = token_channels(small_dataset)
    reading = PerceivedCount(CountingPerception(1 + len(small_dataset.classes), widths=(8, 8, 16, 16)), table)
    single = [q for q in small_dataset.questions if len(q.classes) == 1]
    tokens = torch.nn.utils.rnn.pad_sequence([torch.tensor(q.tokens) for q in single], batch_first=True)
    assert reading.asked_channel(tokens).tolist() == [1 + small_dataset.classes.index(q.classes[0]) for q in single]
    assert table[small_dataset.vocab.encode("how many are there in the bin ?")].eq(0).all()


def test_a_kept_frame_is_the_episodes_state_the_perception_reads_most_in(small_dataset, tmp_path):
    """``kept_frame``: I_stop is the state where the counting perception's expected count of the asked class is
    highest (ties: the later), with that state's measurements (its object map counts its visible areas) and answer
    frame; I_start and the pushes are the episode's, as without it. A missing file and a non-path are refused."""
    from mqa_rl.modules.answering.kept_frame import FrameKeeper
    from mqa_rl.modules.answering.perception import CountingPerception, save_perception
    from mqa_rl.modules.answering.perceived_count import READING
    torch.manual_seed(0)
    path = save_perception(CountingPerception(1 + len(small_dataset.classes), widths=(8, 8, 16, 16)),
                           tmp_path / "perception.pt", {})
    from mqa_rl.envs.sapien_bin import SapienBinEnv
    run = tmp_path / "dqn_run"
    _fake_dqn_run(run, SapienBinEnv(small_dataset, split="train"))
    never_stop = {"kind": "dqn", "run": str(run), "stop_margin": 1e9}
    plan = {**PLAN, "levels": ["hard"], "answer_size": 448, "store_depth": False, "max_pushes": 3, "policy": never_stop}
    plain, kept = tmp_path / "plain", tmp_path / "kept"
    collect_rollouts(plain, dataset=small_dataset, **plan)
    collect_rollouts(kept, dataset=small_dataset, **{**plan, "policy": {**never_stop, "kept_frame": str(path)}})
    a, b = load_records(plain), load_records(kept)
    assert torch.equal(a[keys.FIRST_RGB], b[keys.FIRST_RGB]) and torch.equal(a[keys.PUSHES], b[keys.PUSHES])
    assert (a[keys.PUSHES] == 3).all()
    assert not torch.equal(a[keys.LAST_RGB], b[keys.LAST_RGB])                          # not always the last frame
    keeper = FrameKeeper.from_file(path, small_dataset)
    expected = lambda rgb: keeper.reading(rgb, b[keys.QUESTION])[:, READING.index("perceived_expected")]  # noqa: E731
    assert (expected(b[keys.LAST_RGB]) >= expected(b[keys.FIRST_RGB])).all()
    assert (expected(b[keys.LAST_RGB]) >= expected(a[keys.LAST_RGB])).all()
    last = b[keys.LAST]
    counted = torch.stack([torch.bincount(m.flatten().long(), minlength=1 + v.shape[0])[1:1 + v.shape[0]]
                           for m, v in zip(last[keys.OBJECT_MAP], last[keys.FRAME_VISIBLE])])
    assert torch.equal(counted.float(), last[keys.FRAME_VISIBLE].float())          # one state's measurements
    pooled = torch.nn.functional.avg_pool2d(last[keys.ANSWER_RGB].float(), 2)
    assert (pooled - last[keys.RGB].float()).abs().mean() < 3.0                        # and its answer frame
    with pytest.raises(FileNotFoundError, match="no such perception file"):
        collect_rollouts(tmp_path / "x", dataset=small_dataset, **{**plan, "policy": {**never_stop, "kept_frame": "nope.pt"}})
    with pytest.raises(ValueError, match="must be the path of a counting perception"):
        collect_rollouts(tmp_path / "y", dataset=small_dataset, **{**plan, "policy": {**never_stop, "kept_frame": 3}})


def test_the_frame_keeper_keeps_the_highest_reading_and_the_later_of_equals(small_dataset):
    from mqa_rl.modules.answering.kept_frame import FrameKeeper
    from mqa_rl.modules.answering.perceived_count import READING, PerceivedCount, token_channels
    from mqa_rl.modules.answering.perception import CountingPerception
    torch.manual_seed(0)
    keeper = FrameKeeper(PerceivedCount(CountingPerception(1 + len(small_dataset.classes), widths=(8, 8, 16, 16)),
                                        token_channels(small_dataset)))
    question = torch.tensor(small_dataset.questions[0].tokens)
    frames = torch.randint(0, 256, (4, 3, 112, 112), dtype=torch.uint8)
    states = [TensorDict({keys.RGB: f, keys.QUESTION: question}, []) for f in frames]
    scores = keeper.reading(frames, question.expand(4, -1))[:, READING.index("perceived_expected")]
    best = int(scores.argmax())
    assert keeper.choose(states) == best
    assert keeper.choose([*states, states[best].clone()]) == 4                      # a tie: the later frame
    assert keeper.choose(states[:1]) == 0
    assert torch.equal(keeper.reading.expected(frames, question.expand(4, -1)), scores)   # no clustering, same value
    read = []
    keeper.reading.expected = lambda f, q, real=keeper.reading.expected: read.append(len(f)) or real(f, q)
    assert keeper.choose([*states, states[best].clone(), states[0].clone()]) == 4 and read == [4]   # each frame once


def test_evaluate_policy_reports_the_counter_on_the_frame_kept(small_dataset_dir, small_dataset, tmp_path, monkeypatch):
    """``kept_frame=``: ``counter_kept`` is the perfect counter on the state the keeper chooses: I_start's
    (``counter_start``) when it keeps the first, I_stop's (``counter_stop``) when it keeps the last; likewise
    ``countable_gain_kept``: nothing gained on the first frame, the episode's ``countable_gain`` on the last; and
    ``chi_kept`` / ``hidden_kept``: the start's χ on the first frame, ``chi_end`` / ``hidden_end`` on the last."""
    from mqa_rl.evaluation import policy_units
    from mqa_rl.modules.answering.kept_frame import FrameKeeper
    from mqa_rl.modules.answering.perception import CountingPerception, save_perception
    path = save_perception(CountingPerception(1 + len(small_dataset.classes), widths=(8, 8, 16, 16)),
                           tmp_path / "perception.pt", {})
    setup = {"dataset": str(small_dataset_dir), "split": "train", "qtypes": ["counting"], "max_pushes": 3,
             "pusher": "finger", "push_memory": None, "seed": 3, "episodes": 4, "threshold": 0.2, "frames": {},
             "reward": OmegaConf.to_container(OmegaConf.load(REPO / "recipes" / "conf" / "reward" / "countable.yaml")),
             "kept_frame": str(path), "systems": {"random_masked": system_spec(system_registry(), "random_masked")}}
    try:
        for kept, same_as in ((0, "counter_start"), (-1, "counter_stop")):
            monkeypatch.setattr(FrameKeeper, "choose", lambda self, states, k=kept: range(len(states))[k])
            metrics, _ = policy_units.evaluate_unit(setup, "easy", "random_masked")
            assert metrics["counter_kept"].isfinite().all()
            assert torch.equal(metrics["counter_kept"], metrics[same_as]), same_as
            gain = torch.zeros_like(metrics["countable_gain"]) if kept == 0 else metrics["countable_gain"]
            assert torch.equal(metrics["countable_gain_kept"], gain)
            chi = metrics["chi_start"] if kept == 0 else metrics["chi_end"]
            assert torch.allclose(metrics["chi_kept"], chi, equal_nan=True)
            if kept == -1:
                assert torch.equal(metrics["hidden_kept"].nan_to_num(-1), metrics["hidden_end"].nan_to_num(-1))
        assert metrics["countable_gain"].abs().sum() > 0                               # the last frame gained or lost
        assert not torch.equal(metrics["counter_start"], metrics["counter_stop"])     # the two frames tell apart here
    finally:
        policy_units.close_envs()

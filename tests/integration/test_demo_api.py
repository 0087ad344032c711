"""The web demo through its HTTP API (gradio_client), as a second program or a page would use it:
episodes stream frames and end with the true answer and a video; bad questions and unusable
checkpoints get clear messages; two sessions run at once without interfering; a cancelled episode
gives its env back. The VQA adapter is checked with a stand-in model honouring the VQA's public contract."""

from __future__ import annotations

import tempfile
import threading
import time
from pathlib import Path

import cv2
import gradio_client  # the 'test' extra, pinned in requirements.lock
import httpx
import numpy as np
import pytest
import torch
from demo_helpers import REWARD, make_runs_folder, start_demo, stop_demo
from PIL import Image
from torch_threads import one_torch_thread  # noqa: F401

from mqa_rl import keys
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.envs import actions
from conftest import REPO

RANDOM, RANDOM_MASKED = "random", "random_masked"        # system ids (recipes/conf/systems.yaml)


@pytest.fixture(scope="module")
def served(small_dataset_dir, tmp_path_factory):
    root = tmp_path_factory.mktemp("demo")
    runs = make_runs_folder(root, small_dataset_dir)
    backend, demo, url = start_demo(small_dataset_dir, runs, root / "cache", max_pushes=3, sessions=2)
    yield backend, url
    stop_demo(backend, demo)
    assert not backend.files.root.exists() and not backend.frames.root.exists()    # nothing left on disk


def client(url):
    """A client downloading the files it receives, as a browser fetches the frames and the video."""
    return gradio_client.Client(url, verbose=False, analytics_enabled=False,
                                download_files=tempfile.mkdtemp(prefix="demo_client_"))


def scene_and_question(backend, level: str, qtype: str = "counting"):
    scene = next(s for s in backend.dataset.scenes if s.difficulty == level)
    return scene.id, backend.questions.of_scene(scene.id, qtype)[0]


def run(c, scene_id, question_id, typed="", policy=RANDOM, vqa=None, seed=0):
    job = c.submit(scene_id, question_id, typed, policy, vqa, seed, api_name="/run")
    job.result(timeout=120)
    return job.outputs()


def test_startup_lists_unusable_checkpoints_with_reasons(served):
    backend, url = served
    problems = dict(backend.policies.problems)
    corrupt = next(k for k in problems if "corrupt" in k)
    assert "missing or changed" in problems[corrupt]                    # the SHA-256 check caught the truncation
    stray = next(k for k in problems if k.endswith("model.pt"))
    assert "not a recipes/train_dqn.py run folder" in problems[stray]
    assert [n for n in backend.policies.trained if "good" in n]           # the sound run is offered
    page = httpx.get(url + "config", timeout=30).text
    assert "unusable" in page and "model.pt" in page and "no VQA checkpoint" in page


def test_random_episode_streams_frames_then_answer_and_video(served):
    backend, url = served
    scene_id, q = scene_and_question(backend, "easy")
    outputs = run(client(url), scene_id, q.id, seed=3)
    assert len(outputs) >= 2                                             # step 0 at once, then the steps
    frame, table, probs, answer, video, message = outputs[-1]
    first = outputs[0]
    assert first[0] is not None and "step 0" in first[5] and "running" in first[3]
    assert f"True answer: {q.answer}" in answer and "no VQA checkpoint" in answer
    assert video.endswith(".webm") and Path(video).stat().st_size > 0
    capture = cv2.VideoCapture(video)                                     # VP8 WebM, one frame per state
    assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == len(outputs) and capture.read()[0]
    headers, rows = table["headers"], table["data"]
    assert {"step", "action", "visible (mean)", "R_e", "R_g", "R_l", "β", "reward"} <= set(headers)
    assert len(rows) == len(outputs) and rows[0][headers.index("action")] == "first image"
    assert "done after" in message
    assert Image.open(Path(frame)).width >= 448


def test_q_network_frames_carry_the_q_map(served):
    backend, url = served
    policy = next(n for n in backend.policies.trained if "good" in n)
    scene_id, q = scene_and_question(backend, "hard")
    outputs = run(client(url), scene_id, q.id, policy=policy)
    widths = [Image.open(Path(o[0])).width for o in outputs[1:]]
    assert widths and min(widths) >= 2 * 448                             # the Q-map panel beside every step


@pytest.mark.parametrize(("typed", "expected"), [
    ("", "no question: pick one"),
    ("   ?  ", "empty question"),
    ("How many zebras are there in the bin?", "unknown word(s) 'zebras'"),
    ("Is there a can under the can?", "not one of the dataset's question templates"),
    ("how many cans", "not one of the dataset's question templates"),
])
def test_bad_questions_get_a_clear_message(served, typed, expected):
    backend, url = served
    scene_id, _ = scene_and_question(backend, "easy")
    frame, table, probs, answer, video, message = client(url).predict(scene_id, None, typed, RANDOM, None, 0,
                                                                      api_name="/run")
    assert expected in message and frame is None and video is None
    if "unknown" in expected:
        assert "cans" in message and "under" in message                  # names the accepted words
    if "templates" in expected or "pick one" in expected:
        assert "How many <objects> are there in the bin?" in message


def test_huge_questions_and_seeds_get_a_short_clear_message(served):
    backend, _ = served
    scene_id, q = scene_and_question(backend, "easy")
    huge = "how many cans " * 700                                          # 9,800 characters of known words
    for typed, seed, expected in ((huge, 0, "not one of the dataset's question templates"),
                                  ("zebra " * 2000, 0, "unknown word(s) 'zebra'"),
                                  (None, 2 ** 70, "out of range")):
        updates = list(backend.run_episode(scene_id, q.id, typed, RANDOM, None, seed, "probe"))
        assert len(updates) == 1 and updates[0].done and expected in updates[0].message
        assert len(updates[0].message) < 1500                             # quoted back cut, not whole


def test_typed_question_is_matched_to_the_dataset(served):
    backend, url = served
    scene_id, q = scene_and_question(backend, "easy", "existence")
    outputs = run(client(url), scene_id, None, typed=q.text.upper().rstrip("?"))
    assert f"True answer: {q.answer}" in outputs[-1][3] and q.id in outputs[-1][5]


def test_two_sessions_at_once_do_not_interfere(served):
    backend, url = served
    scene_id, q = scene_and_question(backend, "hard")
    solo = run(client(url), scene_id, q.id, seed=7)[-1][1]["data"]
    busy, stop = [], threading.Event()

    def watch():
        while not stop.is_set():
            busy.append(len(backend.pool.borrowers))
            time.sleep(0.01)

    watcher = threading.Thread(target=watch)
    watcher.start()
    jobs = [client(url).submit(scene_id, q.id, "", RANDOM, None, 7, api_name="/run") for _ in range(2)]
    tables = [job.result(timeout=180)[1]["data"] for job in jobs]
    stop.set()
    watcher.join()
    assert max(busy) == 2                                                # both episodes ran at the same time
    assert tables[0] == tables[1] == solo                                # and each saw only its own scene
    assert backend.pool.free == backend.pool.size


def test_live_frames_are_files_of_their_own_session(served):
    """Two sessions streaming the same frame get files of their own (Gradio caches an array under the hash of its
    bytes and rewrites it in place: a concurrent download of it could read a truncated file)."""
    backend, _ = served
    frame = np.full((32, 32, 3), 127, np.uint8)
    a, b = backend.frame_file("session_a", frame), backend.frame_file("session_b", frame)
    assert a != b and Path(a).read_bytes() == Path(b).read_bytes()
    assert Image.open(a).size == (32, 32)
    for _ in range(6):
        backend.frame_file("session_a", frame)
    assert len(list(Path(a).parent.iterdir())) == 4                    # a long episode keeps only its last frames
    backend.release("session_a")
    assert not Path(a).parent.exists() and Path(b).exists()


class SlowPusher:
    """Pushes at the bin centre, slowly: an episode long enough to be stopped half-way."""

    def __call__(self, td):
        time.sleep(0.5)
        td[keys.ACTION] = torch.tensor(actions.encode(0, 14, 14))
        return td


def test_cancelled_episode_gives_its_env_back(served, monkeypatch):
    from mqa_rl.demo.policies import PolicyEntry

    backend, url = served
    monkeypatch.setitem(backend.policies.entries, RANDOM_MASKED, PolicyEntry(RANDOM_MASKED, actor=SlowPusher()))
    scene_id, q = scene_and_question(backend, "easy")
    c = client(url)
    job = c.submit(scene_id, q.id, "", RANDOM_MASKED, None, 0, api_name="/run")
    deadline = time.time() + 60
    while not job.outputs() and time.time() < deadline:
        time.sleep(0.02)
    job.cancel()                                                         # what Stop and a closed page do
    deadline = time.time() + 30
    while backend.pool.free < backend.pool.size and time.time() < deadline:
        time.sleep(0.05)
    assert backend.pool.free == backend.pool.size and not backend.pool.borrowers
    assert not any("done after" in o[5] for o in job.outputs())           # it was stopped half-way
    assert "done after" in run(c, scene_id, q.id)[-1][5]                 # and the server goes on


# ---------------------------------------------------------------------------------- VQA adapter
class StandInVQA:
    """Honours the VQA's public contract: answer_probs(tokens [B, L], first [B, H, W, 3], last) -> [B, n]."""

    answers = ["0", "1", "2", "3", "yes", "no"]

    def __init__(self, shape_ok=True):
        self.seen = None
        self.shape_ok = shape_ok

    def answer_probs(self, tokens, first_rgb, last_rgb):
        self.seen = (tokens.shape, tokens.dtype, first_rgb.shape, first_rgb.dtype, last_rgb.shape)
        n = len(self.answers) if self.shape_ok else 2
        return torch.softmax(torch.arange(n, dtype=torch.float32), 0)[None]


def test_vqa_answer_is_shown_with_probabilities(served, monkeypatch):
    from mqa_rl.demo import vqa_adapter

    backend, _ = served
    model = StandInVQA()
    monkeypatch.setattr(vqa_adapter, "_load_vqa", lambda: lambda path: model)
    monkeypatch.setattr(backend, "vqa", vqa_adapter.VQARegistry(["checkpoints/vqa_best"]))
    scene_id, q = scene_and_question(backend, "easy")
    last = list(backend.run_episode(scene_id, q.id, None, RANDOM, "vqa_best", 0, "test"))[-1]
    assert model.seen[0][0] == 1 and model.seen[1] == torch.int64 and model.seen[2][-1] == 3
    assert model.seen[3] == torch.uint8 and model.seen[2] == model.seen[4]
    assert last.answer == pytest.approx(dict(zip(model.answers, torch.softmax(torch.arange(6.0), 0).tolist())))
    assert "VQA (vqa_best): **no**" in last.answer_text and f"True answer: {q.answer}" in last.answer_text
    assert "guess" not in last.answer_text                      # no types recorded: nothing to warn about


def test_a_vqa_reading_finer_frames_gets_the_answer_cameras_and_others_the_envs(small_dataset):
    """A VQA whose perception reads 448 px makes the demo's env add the answer camera; the episode's last view
    carries its I_start / I_stop, which that VQA reads, while a 224-px VQA reads the env's frames."""
    from mqa_rl.demo import vqa_adapter
    from mqa_rl.demo.episode import play
    from mqa_rl.modules.push.random_policy import RandomMQAPolicy
    from mqa_rl.transforms.mqa_env import make_mqa_env

    fine, coarse = StandInVQA(), StandInVQA()
    fine.frame_size, coarse.frame_size = 448, 224
    registry = vqa_adapter.VQARegistry([])
    registry.models = {"fine": fine, "coarse": coarse}
    assert registry.answer_size(224) == 448 and vqa_adapter.VQARegistry([]).answer_size(224) is None
    env = make_mqa_env(small_dataset, split=None, max_pushes=1, answer_size=registry.answer_size(224))
    q = small_dataset.select("train", None, ["counting"])[0]
    last = list(play(env, RandomMQAPolicy(max_pushes=1, seed=0), q.id, q.text))[-1]
    assert last.answer_frames[0].shape == (448, 448, 3) and last.first_rgb.shape == (224, 224, 3)
    for name, model, side in (("fine", fine, 448), ("coarse", coarse, 224)):
        assert isinstance(registry.answer(name, last.tokens, last.first_rgb, last.last_rgb, last.answer_frames), dict)
        assert model.seen[2] == model.seen[4] == (1, side, side, 3), name
    env.close()


def test_a_question_type_the_vqa_never_learnt_is_flagged(served, monkeypatch):
    """A VQA trained on COUNTING only still answers an EXISTENCE question, and the page says it is a guess."""
    from mqa_rl.demo import vqa_adapter

    backend, _ = served
    model = StandInVQA()
    model.meta = {"question_types": ["counting"]}
    monkeypatch.setattr(vqa_adapter, "_load_vqa", lambda: lambda path: model)
    monkeypatch.setattr(backend, "vqa", vqa_adapter.VQARegistry(["checkpoints/vqa_counting"]))
    for qtype, flagged in (("existence", True), ("counting", False)):
        scene_id, q = scene_and_question(backend, "easy", qtype)
        last = list(backend.run_episode(scene_id, q.id, None, RANDOM, "vqa_counting", 0, "test"))[-1]
        assert last.answer is not None
        assert ("learnt from COUNTING questions only" in last.answer_text) is flagged
        assert ("EXISTENCE question is a guess" in last.answer_text) is flagged


def test_vqa_problems_are_reported_not_raised(monkeypatch):
    import sys

    from mqa_rl.demo import vqa_adapter

    monkeypatch.setitem(sys.modules, "mqa_rl.modules.answering.vqa", None)         # the module absent
    registry = vqa_adapter.VQARegistry(["some/checkpoint"])
    assert not registry.names and "not in this version" in registry.missing_reason()
    assert registry.answer(None, None, None, None).startswith("no VQA checkpoint")

    def refuse(path):
        raise FileNotFoundError(f"{path} does not exist")

    monkeypatch.setattr(vqa_adapter, "_load_vqa", lambda: refuse)
    registry = vqa_adapter.VQARegistry(["missing.ckpt"])
    assert "FileNotFoundError: missing.ckpt does not exist" in registry.missing_reason()
    monkeypatch.setattr(vqa_adapter, "_load_vqa", lambda: lambda path: StandInVQA(shape_ok=False))
    registry = vqa_adapter.VQARegistry(["odd.ckpt"])
    image = torch.zeros(224, 224, 3, dtype=torch.uint8)
    assert "failed on this episode" in registry.answer("odd.ckpt", torch.ones(12, dtype=torch.int64), image, image)


def test_scene_filters_and_question_lists(served):
    backend, _ = served
    easy_test = backend.catalog.select("easy", "test")
    assert all(c.difficulty == "easy" and c.split == "test" for c in easy_test)
    assert len(backend.catalog.select()) == len(backend.dataset.scenes)
    assert all(np.asarray(Image.open(c.image)).shape == (224, 224, 3) for c in backend.catalog.select())
    scene_id = backend.dataset.scenes[0].id
    assert {q.type for q in backend.questions.of_scene(scene_id)} == set(QUESTION_TYPES)
    with pytest.raises(ValueError, match="unknown level"):
        backend.catalog.select("extreme")


def test_the_shipped_checkpoints_folder_offers_every_policy_and_the_students_learned_stop(small_dataset_dir):
    """runs=checkpoints: the five shipped train_dqn runs, the student and the countable chain again with their fit_stop
    critics (matched by the weights' fingerprint), and the VQA / encoder / recognition folders passed over, not listed as unusable;
    the student with its stop plays an episode that ends with the stop action or the push budget."""
    from mqa_rl.demo.policies import PolicyRegistry
    from mqa_rl.modules.stop.learned_stop import LearnedStop
    from mqa_rl.transforms.mqa_env import make_mqa_env

    root = REPO
    env = make_mqa_env(small_dataset_dir, REWARD, split=None, max_pushes=3)
    try:
        registry = PolicyRegistry(root / "checkpoints", env, max_pushes=3)
        assert not registry.problems, registry.problems
        # the stop reading the counting perception on the answer camera's frame: this env renders none, so not offered
        assert [what for what, _ in registry.passed_over] == ["stop_countable_perceived"]
        assert "448-px" in registry.passed_over[0][1] and "not offered here" in registry.status()
        trained = registry.trained
        shipped_runs = {p.parent.parent.name for p in (root / "checkpoints").glob("*/checkpoints/checkpoint-*")}
        assert len(shipped_runs) == 5
        assert len([n for n in trained if "learned stop" not in n]) == len(shipped_runs)
        stopping = sorted((n for n in trained if "learned stop" in n), key=lambda n: "dqn_countable" in n)
        assert len(stopping) == 2 and "dqn_geometric_student" in stopping[0] and "stop_geometric_student" in stopping[0]
        assert "dqn_countable" in stopping[1] and "stop_countable" in stopping[1]
        entry = registry.get(stopping[0])
        assert isinstance(entry.actor, LearnedStop) and entry.max_pushes == 10 and entry.actor.max_pushes == 10
        rollout = env.rollout(4, registry.make(stopping[0], seed=0), break_when_any_done=True)
        actions_taken = rollout.get(keys.ACTION).reshape(-1).tolist()
        assert all(0 <= a <= actions.STOP for a in actions_taken)
        assert actions_taken[-1] == actions.STOP or len(actions_taken) == 3
    finally:
        env.close()

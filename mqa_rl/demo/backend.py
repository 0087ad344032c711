"""Everything the demo page calls, without Gradio: built once per server, then shared by visitors.

``DemoBackend(DemoConfig(...))`` loads the dataset, builds the env pool (shader compile and env
construction happen here, once), renders or reads the scene images, loads every policy and VQA
checkpoint; ``run_episode`` then streams ``EpisodeUpdate``s for one visitor's episode.
"""

from __future__ import annotations

import logging
import shutil
import tempfile
import time
import uuid
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import torch

from mqa_rl.data.dataset import MQADataset
from mqa_rl.demo.episode import play, table_row, video_frames
from mqa_rl.demo.policies import PolicyRegistry
from mqa_rl.demo.questions import QuestionError, SceneQuestions
from mqa_rl.demo.scenes import SceneCatalog
from mqa_rl.demo.sessions import EnvPool, PoolBusy, SessionFiles
from mqa_rl.demo.vqa_adapter import VQARegistry
from mqa_rl.envs.video import write_video
from mqa_rl.modules.answering.perception import RENDER_SIZE
from mqa_rl.files import write_atomic
from mqa_rl.transforms.mqa_env import make_mqa_env

log = logging.getLogger(__name__)


SEED_LIMIT = 2 ** 32       # numpy's and the env's seeds are 32-bit


def _short_number(value) -> str:
    text = str(value)
    return text if len(text) <= 24 else f"{text[:10]}…({len(text)} digits)"


@dataclass
class DemoConfig:
    dataset: str | Path                      # a generated dataset folder (recipes/make_dataset.py)
    reward: Mapping                          # reward stack of the per-step table (recipes/conf/reward/*.yaml)
    runs: str | Path | None = "runs"         # folder searched for recipes/train_dqn.py runs
    vqa: tuple = ()                          # VQA checkpoint paths (mqa_rl.modules.answering.vqa.load_vqa)
    max_pushes: int = 10                     # pushes before an episode is cut (the env's max_pushes)
    sessions: int = 2                        # episodes running at once, one env each; others queue
    cache_dir: str | Path = "~/.cache/mqa_rl/demo"   # rendered scene images, reused by later starts
    beta_steps: int | None = None            # β counter of the reward stack (None: its horizon, β = 0.5 as trained)
    videos_per_session: int = 3              # episode videos kept per browser session
    policy: str | None = None                # the page's default policy: the first whose name holds this text
                                             # (None, or no match: the first trained one)
    systems: Mapping = field(default_factory=dict)   # systems of the registry offered by id (id -> spec: random,
                                                     # random_masked, none; recipes/conf/systems.yaml)


@dataclass
class EpisodeUpdate:
    """One streamed update: a frame and the table so far; the answer and video at the end."""

    frame: np.ndarray | None = None
    rows: list[dict] = field(default_factory=list)
    message: str = ""                          # status line (errors included)
    answer: dict[str, float] | None = None     # VQA probabilities
    answer_text: str = ""                      # true answer next to the VQA's (or why there is none)
    video: Path | None = None
    done: bool = False
    step: int = 0                              # env steps done (0: the first image)


class DemoBackend:
    def __init__(self, cfg: DemoConfig):
        t0 = time.perf_counter()
        self.cfg = cfg
        self.dataset = MQADataset(cfg.dataset)
        self.questions = SceneQuestions(self.dataset)
        reward = dict(cfg.reward)
        steps = int(reward.get("beta_horizon", 2000)) if cfg.beta_steps is None else int(cfg.beta_steps)
        self._beta_counter = torch.tensor(steps, dtype=torch.int64)
        self.vqa = VQARegistry(cfg.vqa)         # before the simulators: a VQA reading finer frames adds their camera
        self.pool = EnvPool(self._make_env, cfg.sessions)
        env = self.pool.envs[0]
        td = env.reset(question_id=self.dataset.questions[0].id)       # shaders compiled here, once per server
        self.table_columns = list(table_row(0, td, None))
        self.camera = env.base_env.camera
        self.catalog = SceneCatalog(self.dataset, self.camera, cfg.cache_dir)
        self.policies = PolicyRegistry(cfg.runs, env, cfg.max_pushes, cfg.systems)
        chosen = [n for n in self.policies.names if cfg.policy and cfg.policy in n]
        self.default_policy = (chosen or self.policies.trained or self.policies.names)[0]
        self.files = SessionFiles(tempfile.mkdtemp(prefix="mqa_demo_"))
        self.frames = SessionFiles(tempfile.mkdtemp(prefix="mqa_demo_frames_"))
        self.startup_s = time.perf_counter() - t0
        log.info("demo ready in %.1f s: %d scenes, %d policies, %d VQA", self.startup_s, len(self.catalog.cards),
                 len(self.policies.names), len(self.vqa.names))

    def _make_env(self):
        return make_mqa_env(self.dataset, self.cfg.reward, counter=self._beta_counter, split=None,
                            max_pushes=self.cfg.max_pushes, answer_size=self.vqa.answer_size(RENDER_SIZE))

    def status(self) -> str:
        """Markdown shown under the title: dataset, policies, VQA, and what is missing."""
        return (f"Dataset `{self.dataset.root}`: {len(self.dataset.scenes)} scenes. "
                f"{self.cfg.sessions} simulator(s), up to {self.cfg.max_pushes} pushes per episode.\n\n"
                f"{self.policies.status()}\n\n{self.vqa.status()}")

    def close(self) -> None:
        """The simulators go, and the sessions' videos and frames with them."""
        self.pool.close()
        for files in (self.files, self.frames):
            shutil.rmtree(files.root, ignore_errors=True)

    # ------------------------------------------------------------------------------ episode
    def resolve_question(self, scene_id: str, question_id: str | None, typed: str | None):
        """The typed question when there is one (``QuestionError`` if the dataset lacks it), else the pick."""
        if typed and typed.strip():
            return self.questions.parse(scene_id, typed)
        if not question_id:
            raise QuestionError("no question: pick one of the scene's questions, or type one following a "
                                f"template: {self.questions.templates_help()}")
        question = self.questions.get(question_id)
        if question.scene_id != scene_id:
            raise QuestionError(f"question {question_id} belongs to {question.scene_id}, not to {scene_id}")
        return question

    def run_episode(self, scene_id: str, question_id: str | None, typed: str | None, policy: str,
                    vqa: str | None, seed: int, session: str) -> Iterator[EpisodeUpdate]:
        """Stream one episode: a first update at once, one per step, the last with answer and video."""
        t0 = time.perf_counter()
        try:
            self.catalog.card(scene_id)
            question = self.resolve_question(scene_id, question_id, typed)
            self.policies.get(policy)
            if not 0 <= int(seed) < SEED_LIMIT:
                raise ValueError(f"seed {_short_number(seed)} is out of range: use a whole number from 0 to {SEED_LIMIT - 1}")
        except (QuestionError, KeyError, ValueError) as error:
            yield EpisodeUpdate(message=str(error.args[0] if error.args else error), done=True)
            return
        actor = self.policies.make(policy, int(seed))
        rows = []
        try:
            with self.pool.borrow(session) as env:
                for view in play(env, actor, question.id, question.text):
                    rows.append(view.row)
                    update = EpisodeUpdate(frame=view.frame, rows=list(rows), step=view.step,
                                           message=f"{question.id}: step {view.step} of at most {self.cfg.max_pushes}")
                    if view.done:
                        last = view
                    else:
                        yield update
        except PoolBusy as error:
            yield EpisodeUpdate(message=str(error), done=True)
            return
        except Exception as error:                       # noqa: BLE001 - shown on the page, logged in full
            log.exception("episode %s with %s failed", question.id, policy)
            yield EpisodeUpdate(message=f"the episode failed: {type(error).__name__}: {error}", rows=rows, done=True)
            return
        update.answer, update.answer_text = self._answer(question, vqa, last)
        update.video = self._video(last, question, session)
        update.done = True
        update.message = f"{question.id}: done after {len(rows) - 1} step(s) in {time.perf_counter() - t0:.1f} s"
        yield update

    def _answer(self, question, vqa: str | None, last) -> tuple[dict[str, float] | None, str]:
        result = self.vqa.answer(vqa, last.tokens, last.first_rgb, last.last_rgb, last.answer_frames)
        truth = f"**True answer: {question.answer}**"
        if isinstance(result, str):
            return None, f"{truth} · {result}"
        best = max(result, key=result.get)
        mark = "right" if best == question.answer else "wrong"
        text = f"{truth} · VQA ({vqa}): **{best}** (p = {result[best]:.2f}, {mark})"
        warning = self.vqa.unlearnt_type(vqa, question.type)
        return result, text + (f" · {warning}" if warning else "")

    def frame_file(self, session: str, frame: np.ndarray) -> str:
        """The live frame as a JPEG file of the session's. Gradio caches an array under the hash of its bytes and
        writes it in place, so two sessions streaming the same frame at once (same scene, policy and seed) could
        serve each other a truncated file; a file path it copies under a staging name and renames."""
        ok, jpeg = cv2.imencode(".jpg", cv2.cvtColor(frame, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 90])
        if not ok:
            raise OSError(f"OpenCV cannot encode a live frame of shape {frame.shape} as JPEG")
        path = write_atomic(self.frames.folder(session) / f"frame_{uuid.uuid4().hex[:12]}.jpeg", jpeg.tobytes())
        self.frames.keep_last(session, 4)       # Gradio has copied the earlier ones by the time the next is made
        return str(path)

    def release(self, session: str) -> None:
        """The browser session ended: its videos and frames go."""
        self.files.release(session)
        self.frames.release(session)

    def _video(self, last, question, session: str) -> Path | None:
        path = self.files.folder(session) / f"episode_{uuid.uuid4().hex[:8]}.webm"
        try:
            write_video(video_frames(last.rollout, self.camera, question.text), path)
        except (RuntimeError, OSError) as error:
            log.warning("episode video not written: %s", error)
            return None
        self.files.keep_last(session, self.cfg.videos_per_session)
        return path

"""SapienBinEnv: the MQA bin scene on SAPIEN 3 physics as a TorchRL environment.

Task sheet
----------
* **Scene**: one of the dataset's settled bin scenes (20 / 35 / 50 objects), rebuilt from its stored
  poses at every reset (bit-identical physics; an in-place restore is not).
* **Question**: sampled from the chosen split / difficulty levels / question types, or fixed with
  ``env.reset(question_id="scene_003/counting/can")`` (or a ``"reset_question"`` index into
  ``MQADataset.questions`` in the reset tensordict, for batched and remote envs; negative: random; every
  observation carries it as -1, so that batched envs keep it).
* **Observation**: ``rgb`` uint8 [3, H, W], ``depth`` float32 [1, H, W] (metres), ``question`` int64
  tokens [L], and ``info`` measurements (see ``mqa_rl.keys``): object positions, visible area A_s,
  full projected area A_t, overlap χ, target mask, stop flag, executed push.
* **Action**: ``Categorical(6273)``; see ``mqa_rl.envs.actions`` for the layout (8 directions × 28 ×
  28 cells, then stop). The observation ``action_mask`` marks the pushes that start inside the bin
  (their surface point inside the inner walls: from the bin and camera geometry and the depth image,
  see ``actions.push_start_mask``) and stop; masked pushes stay legal to execute, policies simply
  never need them. A push starts at the surface point under the cell centre (from depth), travels a
  quarter of the image width measured on the bin floor, then the pusher leaves the camera's view and
  the scene settles (until every body sleeps or moves slower than ``settle_speed``, at most
  ``settle_steps``).
* **Episode end**: stop → ``terminated``; ``max_pushes`` pushes → ``truncated``. A ``step`` after that
  raises ``RuntimeError`` until ``reset()`` (TorchRL's rollouts and collectors reset on done).
* **Pusher**: ``pusher="finger"`` (default, a force-limited capsule) or ``"arm"`` (a Panda with a
  stick, ``mqa_rl.sim.arm_pusher``; needs ``pip install 'mqa_rl[arm]'``), or any ``Pusher`` object.
* **Answer camera**: ``answer_size`` (a multiple of ``image_size``, e.g. 448) adds a second camera at the same
  pose and field of view; ``env.answer_image()`` renders the scene as it stands through it. The answering half
  reads I_start / I_stop there (small targets are slivers at 224 px: docs/perception.md, "Resolution") while the
  observation, and with it the push grid, stays at ``image_size``. ``answer_observation=True`` puts that image in
  every observation as well (``answer_rgb``; ~0.2 s a state at 448 px): for a policy that reads the finer view as it
  acts (a stop reading the counting perception, ``mqa_rl.modules.answering.perceived_count``).
* **Reward**: always 0 here. The env measures; ``mqa_rl.transforms`` turn measurements into reward.

>>> env = SapienBinEnv("data/mqa", split="train", question_types=["counting"])   # doctest: +SKIP
>>> td = env.reset(question_id="scene_000/counting/can")                          # doctest: +SKIP
>>> td = env.rand_step(td)                                                        # doctest: +SKIP
"""

from __future__ import annotations

import copy

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Binary, Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from mqa_rl import keys
from mqa_rl.data.dataset import MQADataset
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.data.scenes import MAX_OBJECTS  # noqa: F401  (re-exported: the env's object slots)
from mqa_rl.envs import actions
from mqa_rl.envs.measurements import overlap_rate
from mqa_rl.sim.geometry import CameraSpec
from mqa_rl.sim.pusher import FingerPusher, Pusher, PushResult
from mqa_rl.sim.pushers import make_pusher
from mqa_rl.sim.scene import BinWorld, build_world
from mqa_rl.sim.silhouette import SilhouetteProjector


def _one_integer(value, name: str, allowed: str) -> int:
    """A one-element integer tensor as an int; a float (never truncated), bool or several values are refused."""
    if not isinstance(value, torch.Tensor) or value.numel() != 1:
        raise ValueError(f"{name} must be {allowed}; got {value!r}")
    if value.dtype.is_floating_point or value.dtype.is_complex or value.dtype == torch.bool:
        raise ValueError(f"{name} must be {allowed}; got dtype {value.dtype} ({value.item()})")
    return int(value.item())


def _execution_info(push: PushResult | None) -> dict:
    """How the pusher executed ``push`` (``keys.PUSH_UNREACHABLE``, ``ARM_COLLISION``, ``TIP_ERROR``); all
    zero when there was no push."""
    return {
        keys.PUSH_UNREACHABLE: torch.tensor([push is not None and not push.reachable]),
        keys.ARM_COLLISION: torch.tensor([push is not None and push.arm_collision]),
        keys.TIP_ERROR: torch.tensor([push.tip_error_mean, push.tip_error_max] if push else [0.0, 0.0], dtype=torch.float32),
    }


class SapienBinEnv(EnvBase):
    """The MQA bin scene (see the module docstring for the task sheet)."""

    def __init__(
        self,
        dataset: MQADataset | str,
        *,
        split: str | None = "train",
        difficulties=None,
        question_types=None,
        image_size: int = 224,
        answer_size: int | None = None,
        answer_observation: bool = False,
        max_pushes: int = 10,
        settle_steps: int = 240,
        settle_speed: float = 0.005,
        pusher: Pusher | str | None = None,
        seed: int | None = None,
        device="cpu",
    ):
        super().__init__(device=device, batch_size=torch.Size([]))
        self.dataset = dataset if isinstance(dataset, MQADataset) else MQADataset(dataset)
        self.questions = self.dataset.select(split, difficulties, question_types)
        if not self.questions:
            raise ValueError(f"no question in {self.dataset.root} matches split={split!r}, "
                             f"difficulties={difficulties!r}, question_types={question_types!r}")
        if max_pushes < 1:
            raise ValueError(f"max_pushes must be ≥ 1, got {max_pushes}")
        base = self.dataset.camera
        self.camera = CameraSpec(image_size, image_size, base.fovy_deg, base.distance, base.near, base.far)
        self.answer_camera = _answer_camera(self.camera, answer_size)
        if answer_observation and self.answer_camera is None:
            raise ValueError(f"answer_observation=True puts the answer camera's image in every observation: give "
                             f"answer_size (a multiple of image_size={image_size}, e.g. {2 * image_size}), now {answer_size!r}")
        self.answer_observation = bool(answer_observation)
        self.push_length = self.camera.floor_width() / 4
        self.max_pushes = max_pushes
        self.settle_steps = settle_steps
        self.settle_speed = settle_speed
        self.pusher = make_pusher(pusher) if isinstance(pusher, str) else (pusher if pusher is not None else FingerPusher())
        self.question_length = max(len(q.tokens) for q in self.dataset.questions)
        self._question_index = {q.id: i for i, q in enumerate(self.dataset.questions)}
        self._answer_index = {a: i for i, a in enumerate(self.dataset.answers)}
        self._rng = np.random.default_rng(seed)
        self.world: BinWorld | None = None
        self.question = None
        self._done = False
        self._make_specs()

    # ------------------------------------------------------------------------------------ specs
    def _make_specs(self) -> None:
        h = w = self.camera.height
        k = MAX_OBJECTS
        f32, i64 = torch.float32, torch.int64
        info = Composite(
            object_pos=Unbounded(shape=(k, 3), dtype=f32),
            visible_area=Unbounded(shape=(k,), dtype=f32),
            full_area=Unbounded(shape=(k,), dtype=f32),
            overlap=Bounded(0.0, 1.0, shape=(k,), dtype=f32),
            object_mask=Binary(n=k, shape=(k,), dtype=torch.bool),
            target_mask=Binary(n=k, shape=(k,), dtype=torch.bool),
            is_stop=Categorical(2, shape=(1,), dtype=torch.bool),
            push_start=Unbounded(shape=(3,), dtype=f32),
            push_end=Unbounded(shape=(3,), dtype=f32),
            question_index=Bounded(0, len(self.dataset.questions) - 1, shape=(1,), dtype=i64),
            answer=Categorical(len(self.dataset.answers), shape=(1,), dtype=i64),
            push_count=Bounded(0, self.max_pushes, shape=(1,), dtype=i64),
            question_type=Categorical(len(QUESTION_TYPES), shape=(1,), dtype=i64),
            push_unreachable=Categorical(2, shape=(1,), dtype=torch.bool),
            arm_collision=Categorical(2, shape=(1,), dtype=torch.bool),
            tip_error=Unbounded(shape=(2,), dtype=f32),
            target_cells=Bounded(0.0, 1.0, shape=(actions.GRID, actions.GRID), dtype=f32),
        )
        self.observation_spec = Composite(
            rgb=Bounded(0, 255, shape=(3, h, w), dtype=torch.uint8),
            depth=Unbounded(shape=(1, h, w), dtype=f32),
            question=Categorical(len(self.dataset.vocab), shape=(self.question_length,), dtype=i64),
            action_mask=Binary(n=actions.NUM_ACTIONS, shape=(actions.NUM_ACTIONS,), dtype=torch.bool),
            info=info,
        )
        if self.answer_observation:
            size = self.answer_camera.height
            self.observation_spec[keys.ANSWER_RGB] = Bounded(0, 255, shape=(3, size, size), dtype=torch.uint8)
        self.action_spec = Categorical(actions.NUM_ACTIONS, shape=(), dtype=i64)
        # Read by reset: declared as state so that a TransformedEnv passes it on, and observed (always -1, a
        # random question next) so that SerialEnv / ParallelEnv, which return only observations, keep it too.
        reset_question = Bounded(-1, len(self.dataset.questions) - 1, shape=(1,), dtype=i64)
        self.observation_spec[keys.RESET_QUESTION] = reset_question
        self.state_spec = Composite({keys.RESET_QUESTION: reset_question.clone()})
        self.reward_spec = Unbounded(shape=(1,), dtype=f32)
        self.done_spec = Composite(
            done=Categorical(2, shape=(1,), dtype=torch.bool),
            terminated=Categorical(2, shape=(1,), dtype=torch.bool),
            truncated=Categorical(2, shape=(1,), dtype=torch.bool),
        )

    # ------------------------------------------------------------------------------------ reset
    def _pick_question(self, tensordict, question_id):
        if question_id is not None:
            if question_id not in self._question_index:
                raise ValueError(f"unknown question id {question_id!r}; ids look like {self.questions[0].id!r} "
                                 f"(see env.questions or MQADataset.questions)")
            return self.dataset.question(question_id)
        if tensordict is not None and keys.RESET_QUESTION in tensordict.keys():
            idx = self._reset_index(tensordict.get(keys.RESET_QUESTION))
            if idx >= 0:
                return self.dataset.questions[idx]
        return self.questions[int(self._rng.integers(len(self.questions)))]

    def _reset_index(self, value) -> int:
        """The ``reset_question`` index: one integer (never a float to truncate), < the number of questions."""
        n = len(self.dataset.questions)
        allowed = f"one integer index into MQADataset.questions, in [0, {n}) (negative: a random question)"
        idx = _one_integer(value, keys.RESET_QUESTION, allowed)
        if idx >= n:
            raise ValueError(f"{keys.RESET_QUESTION}={idx} outside [0, {n}): must be {allowed}")
        return idx

    def _reset(self, tensordict: TensorDictBase | None = None, question_id: str | None = None, **kwargs) -> TensorDictBase:
        question = self._pick_question(tensordict, question_id)
        scene = self.dataset.scene(question.scene_id)
        assets = self.dataset.assets(scene)
        self.world = build_world(assets, scene.poses, bin_spec=self.dataset.bin, camera=self.camera,
                                 answer_camera=self.answer_camera)
        self.pusher.attach(self.world)
        self.question = question
        self._projector = SilhouetteProjector([list(a.collision_parts) for a in assets], self.camera)
        self._target = np.array([a.class_name in question.classes for a in assets])
        self._object_class = np.array([1 + self.dataset.classes.index(a.class_name) for a in assets])  # 0: no object
        self._push_count = 0
        self._done = False
        tokens = torch.zeros(self.question_length, dtype=torch.int64)
        tokens[: len(question.tokens)] = torch.tensor(question.tokens)
        self._tokens = tokens
        obs = self._observe(None)
        self._last = obs
        return obs.clone(False)

    # ------------------------------------------------------------------------------------ step
    def _validate_action(self, tensordict: TensorDictBase) -> int:
        if self.world is None:
            raise RuntimeError("call reset() before step()")
        if self._done:
            raise RuntimeError("the episode is over (it stopped or reached max_pushes): call reset() before the next step()")
        allowed = f"one integer index in [0, {actions.NUM_ACTIONS}) (pushes 0…{actions.STOP - 1}, stop {actions.STOP})"
        value = _one_integer(tensordict.get(keys.ACTION, None), keys.ACTION, allowed)
        if not 0 <= value < actions.NUM_ACTIONS:
            raise ValueError(f"action {value} out of range: must be {allowed}")
        return value

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = self._validate_action(tensordict)
        if action == actions.STOP:
            out = self._last.clone()
            out[keys.IS_STOP] = torch.ones(1, dtype=torch.bool)
            out[keys.PUSH_START] = torch.zeros(3)
            out[keys.PUSH_END] = torch.zeros(3)
            out.update(_execution_info(None))
            terminated = True
        else:
            result = self._execute_push(action)
            self._push_count += 1
            out = self._observe(result)
            terminated = False
        truncated = (not terminated) and self._push_count >= self.max_pushes
        self._done = terminated or truncated
        self._last = out
        out = out.clone(False)
        out.set(keys.REWARD, torch.zeros(1))
        out.set("terminated", torch.tensor([terminated]))
        out.set("truncated", torch.tensor([truncated]))
        out.set("done", torch.tensor([terminated or truncated]))
        return out

    def _execute_push(self, action: int) -> PushResult:
        d, row, col = actions.decode(action)
        start = self._starts[row, col]                 # the surface under the cell, from the last depth image
        result = self.pusher.push(self.world, start, actions.direction_xy(d), self.push_length)
        self.world.settle(self.settle_steps, check_every=8, speed_tol=self.settle_speed)
        return result

    # ------------------------------------------------------------------------------------ measure
    def measure(self) -> dict[str, np.ndarray]:
        """Render and measure the current scene (numpy): the images and per-object areas."""
        rgb, depth, seg = self.world.render()
        poses = self.world.poses()
        ids = self.world.entity_ids()
        visible = np.bincount(seg.ravel(), minlength=int(ids.max()) + 1)[ids].astype(np.float32)
        full = self._projector.areas(poses).astype(np.float32)
        overlap = overlap_rate(torch.from_numpy(visible), torch.from_numpy(full)).numpy()
        return {"rgb": rgb, "depth": depth, "seg": seg, "poses": poses, "visible": visible, "full": full, "overlap": overlap}

    def answer_image(self) -> torch.Tensor | None:
        """uint8 [3, S, S]: the scene as it stands through the answer camera (``answer_size`` px a side), the frames
        the answering half reads (I_start, I_stop); None when the env has no answer camera (then they are ``rgb``)."""
        if self.world is None:
            raise RuntimeError("call reset() before answer_image()")
        if self.answer_camera is None:
            return None
        return torch.from_numpy(np.ascontiguousarray(self.world.render_answer().transpose(2, 0, 1)))

    def ground_truth(self) -> dict:
        """What only the simulator knows, for oracle references (never for learning): ``measure()``
        plus every object's full silhouette mask [N, H, W], its segmentation id, the target mask and
        the episode's question / scene ids and push count."""
        if self.world is None:
            raise RuntimeError("call reset() before ground_truth()")
        m = dict(self._last_measure)               # the scene has not changed since it was observed
        m.update(masks=self._projector.masks(m["poses"]), entity_ids=self.world.entity_ids(), target=self._target.copy(),
                 question_id=self.question.id, scene_id=self.question.scene_id, push_count=self._push_count)
        return m

    def preview(self, action: int) -> dict:
        """``measure()`` of the scene after push ``action``, simulated on a copy rebuilt at the current
        poses; the episode itself is untouched. For oracle references that plan by lookahead."""
        if self.world is None:
            raise RuntimeError("call reset() before preview()")
        world, pusher = self.world, self.pusher
        try:
            self.world = build_world(world.assets, world.poses(), bin_spec=world.bin, camera=self.camera)
            self.pusher = copy.copy(pusher)
            self.pusher.attach(self.world)
            self._execute_push(int(action))
            return self.measure()
        finally:
            self.world, self.pusher = world, pusher

    def _observe(self, push: PushResult | None) -> TensorDict:
        m = self.measure()
        self._last_measure = m
        self._starts = actions.push_start_points(m["depth"], self.camera)
        n, k = len(m["poses"]), MAX_OBJECTS

        def pad(x, dtype):
            out = torch.zeros((k, *x.shape[1:]), dtype=dtype)
            out[:n] = torch.as_tensor(x, dtype=dtype)
            return out

        info = {
            "object_pos": pad(m["poses"][:, :3], torch.float32),
            "visible_area": pad(m["visible"], torch.float32),
            "full_area": pad(m["full"], torch.float32),
            "overlap": pad(m["overlap"], torch.float32),
            "object_mask": pad(np.ones(n, bool), torch.bool),
            "target_mask": pad(self._target, torch.bool),
            "is_stop": torch.zeros(1, dtype=torch.bool),
            "push_start": torch.as_tensor(push.start if push else np.zeros(3), dtype=torch.float32),
            "push_end": torch.as_tensor(push.end if push else np.zeros(3), dtype=torch.float32),
            "question_index": torch.tensor([self._question_index[self.question.id]]),
            "answer": torch.tensor([self._answer_index[self.question.answer]]),
            "push_count": torch.tensor([self._push_count]),
            "question_type": torch.tensor([QUESTION_TYPES.index(self.question.type)]),
            "target_cells": torch.from_numpy(self._target_cells(m["seg"])),
        }
        info.update({k[1]: v for k, v in _execution_info(push).items()})
        obs = {
            keys.RGB: torch.from_numpy(np.ascontiguousarray(m["rgb"].transpose(2, 0, 1))),
            keys.DEPTH: torch.from_numpy(m["depth"][None].copy()),
            keys.QUESTION: self._tokens.clone(),
            keys.ACTION_MASK: actions.start_points_mask(self.dataset.bin, self._starts),
            keys.INFO: info,
            # the state the next reset reads unless told otherwise: -1, a random question (auto-resets stay random)
            keys.RESET_QUESTION: torch.full((1,), -1, dtype=torch.int64),
        }
        if self.answer_observation:
            obs[keys.ANSWER_RGB] = self.answer_image()
        return TensorDict(obs, batch_size=[])

    def _target_cells(self, seg: np.ndarray) -> np.ndarray:
        """Fraction of each action-grid cell's pixels where a target is visible (from the segmentation)."""
        return _cell_fractions(np.isin(seg, self.world.entity_ids()[self._target]).astype(np.float32)[None])[0]

    def class_cells(self) -> np.ndarray:
        """[1 + classes, GRID, GRID]: fraction of each action-grid cell's pixels showing each object class
        (channel 1 + ``dataset.classes.index(name)``; channel 0: no object, i.e. bin or floor) in the last
        observation. The simulator's segmentation: a pretraining signal (``recipes/pretrain.py part=push_trunk``),
        never a policy input."""
        if self.world is None:
            raise RuntimeError("call reset() before class_cells()")
        seg = self._last_measure["seg"]
        lut = np.zeros(int(max(seg.max(), self.world.entity_ids().max())) + 1, np.int64)
        lut[self.world.entity_ids()] = self._object_class
        labels = lut[seg]
        onehot = (labels[None] == np.arange(1 + len(self.dataset.classes))[:, None, None]).astype(np.float32)
        return _cell_fractions(onehot)

    def _set_seed(self, seed: int | None) -> None:
        self._rng = np.random.default_rng(seed)


def _answer_camera(camera: CameraSpec, size: int | None) -> CameraSpec | None:
    """The answer camera: ``camera``'s view at ``size`` px a side; None when ``size`` is None or the same."""
    if size is None or int(size) == camera.height:
        return None
    if isinstance(size, bool) or int(size) != size or size < camera.height or size % camera.height:
        raise ValueError(f"answer_size must be a multiple of image_size ({camera.height}), e.g. {2 * camera.height}, "
                         f"or null for none; got {size!r}")
    size = int(size)
    return CameraSpec(size, size, camera.fovy_deg, camera.distance, camera.near, camera.far)


def _cell_fractions(masks: np.ndarray) -> np.ndarray:
    """Float masks [C, H, W] → [C, GRID, GRID]: their mean over each action-grid cell's pixels."""
    c, h, w = masks.shape
    if h % actions.GRID == 0 and w % actions.GRID == 0:          # equal cells (224 px: 8 × 8 each)
        return masks.reshape(c, actions.GRID, h // actions.GRID, actions.GRID, w // actions.GRID).mean((2, 4)).astype(np.float32)
    rows = (np.arange(h) * actions.GRID) // h            # pixel -> grid row / column (any image size)
    cols = (np.arange(w) * actions.GRID) // w
    cells = np.zeros((c, actions.GRID, actions.GRID), np.float32)
    np.add.at(cells, (slice(None), rows[:, None], cols[None, :]), masks)
    counts = np.bincount(rows, minlength=actions.GRID)[:, None] * np.bincount(cols, minlength=actions.GRID)[None, :]
    return (cells / counts).astype(np.float32)

"""Rollouts of a frozen policy over a set of questions, stored for the VQA: per episode the question,
its answer and type, scene and level, I_start and I_stop (rgb uint8, depth float16; with ``answer_size`` also the
answer camera's finer rgb, which a VQA whose perception reads that size takes instead), the per-object
measurements of both frames, pushes used and the targets' mean χ at start and end. A policy spec with
``kept_frame`` stores as I_stop the state its ``FrameKeeper`` keeps (``mqa_rl.modules.answering.kept_frame``), not
the last.

    collect_rollouts("runs/answering/rollouts/counting/random/train", dataset="data/mqa",
                     policy={"kind": "random"}, split="train", question_types=["counting"], repeats=3)

The plan: the chosen questions (optionally at most ``max_per_group`` per question type and level,
drawn with ``seed``), each rolled out ``repeats`` times (once for a deterministic policy: the env
replays bit-identically, so repeats would be copies). Slot ``i·repeats + r`` is question i's r-th
rollout; its episode is seeded from (seed, slot), so a slot gives the same episode whichever worker
runs it and whenever. Episodes run in ``workers`` spawned processes (each builds its env and policy
once; one torch thread each), or with ``backend="ray"`` in as many Ray actors of one CPU each, on the
cluster at ``ray_address`` or a local Ray (``mqa_rl.collectors.ray_pool``: a dead actor's episode is run
again elsewhere). Only this process writes, in chunks to an ``EpisodeStore`` (atomic, resumable: run the
same call again after an interruption). Local workers exit by themselves if the parent is killed.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import multiprocessing as mp
import os
import threading
import time
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.envs.utils import set_exploration_type

from mqa_rl import keys
from mqa_rl.data.dataset import LEVELS, MQADataset, dataset_fingerprint
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.collectors.ray_pool import RayPool, check_backend, ray_session
from mqa_rl.collectors.store import META, EpisodeStore, read_meta
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.modules.frozen_policies import is_deterministic, make_frozen_policy, reading_env_options, resolve_checkpoint
from mqa_rl.modules.answering.kept_frame import FrameKeeper, episode_states
from mqa_rl.progress import Progress
from mqa_rl.transforms.episode_stats import mean_target_chi
from mqa_rl.transforms.mqa_env import make_mqa_env

SCHEMA = 1
IN_PROCESS_BELOW = 8             # fewer episodes than this to collect: no worker processes


def plan_questions(dataset: MQADataset, split: str, question_types, levels=None, max_per_group: int | None = None,
                   seed: int = 0) -> list[int]:
    """Indices into ``dataset.questions``: those of ``split`` / types / levels, at most ``max_per_group``
    per (type, level) drawn with ``seed`` (sorted: the plan does not depend on the draw order)."""
    index = {q.id: i for i, q in enumerate(dataset.questions)}
    chosen = []
    for qtype in question_types:
        for level in levels or LEVELS:
            group = [index[q.id] for q in dataset.select(split, [level], [qtype])]
            if max_per_group is not None and len(group) > max_per_group:
                rng = np.random.default_rng([seed, QUESTION_TYPES.index(qtype), LEVELS.index(level)])
                group = sorted(rng.choice(group, size=max_per_group, replace=False).tolist())
            chosen += group
    return sorted(chosen)


def questions_sha256(questions: list[int]) -> str:
    """Fingerprint of a plan's question list (stored in the rollouts' meta; evaluate.py compares it)."""
    return hashlib.sha256(json.dumps([int(q) for q in questions]).encode()).hexdigest()


def episode_seed(seed: int, slot: int) -> int:
    return int(np.random.SeedSequence([seed, slot]).generate_state(1)[0])


# ----------------------------------------------------------------------------------------- one episode
def object_map(env: SapienBinEnv) -> torch.Tensor:
    """uint8 [H, W] of the env's current image: 0 = bin and floor, 1 + the object's slot (the scene's
    order, as ``info`` pads them) for object pixels. From the simulator's segmentation: training
    labels for the VQA's encoder (classes, object centres; as EQA pretrained its CNN on its
    simulator's), never an input of a policy or of the VQA."""
    gt = env.ground_truth()
    seg, ids = gt["seg"], gt["entity_ids"]
    lut = np.zeros(int(max(seg.max(), ids.max())) + 1, dtype=np.uint8)
    lut[ids] = np.arange(1, len(ids) + 1)
    return torch.from_numpy(lut[seg])


def _frame(td, store_depth: bool, omap: torch.Tensor | None, answer: torch.Tensor | None) -> TensorDict:
    out = {keys.RGB: td.get(keys.RGB), keys.FRAME_OVERLAP: td.get(keys.OVERLAP),
           keys.FRAME_VISIBLE: td.get(keys.VISIBLE_AREA), keys.FRAME_FULL: td.get(keys.FULL_AREA)}
    if answer is not None:
        out[keys.ANSWER_RGB] = answer
    if store_depth:
        out[keys.DEPTH] = td.get(keys.DEPTH).to(torch.float16)
    if omap is not None:
        out[keys.OBJECT_MAP] = omap
    return TensorDict(out, batch_size=[])


def _chi(td) -> torch.Tensor:
    has_target = td.get(keys.TARGET_MASK).any()
    return torch.where(has_target, mean_target_chi(td).squeeze(-1), torch.tensor(float("nan")))


def _answer_frame(env, td) -> torch.Tensor | None:
    """The answer camera's image of the state ``td`` observes: the observation's own (``answer_observation``), else
    rendered now (the env stands in that state)."""
    return td.get(keys.ANSWER_RGB) if keys.ANSWER_RGB in td.keys() else env.answer_image()


def run_question_episode(env: SapienBinEnv, policy, exploration, question_index: int, *, max_pushes: int,
                         slot: int = 0, repeat: int = 0, seed: int = 0, store_depth: bool = True,
                         store_object_map: bool = True, keeper: FrameKeeper | None = None) -> TensorDict:
    """One episode of ``policy`` on a question (by index into the env's dataset) → its record. ``keeper``: I_stop is
    the frame it keeps (its state's measurements with it), not the last; ``pushes`` stays the episode's."""
    question = env.dataset.questions[question_index]
    torch.manual_seed(episode_seed(seed, slot))
    td = env.reset(question_id=question.id)
    maps = [object_map(env)] if store_object_map else None
    first_answer = _answer_frame(env, td)
    # a kept frame may be any state's: its object map is taken while the env stands there (not after the last step)
    each_step = (lambda e, _: maps.append(object_map(e))) if keeper is not None and maps is not None else None
    with torch.no_grad(), set_exploration_type(exploration):
        traj = env.rollout(max_pushes + 1, policy, auto_reset=False, tensordict=td, break_when_any_done=True,
                           callback=each_step)
    if not bool(traj["next", "done"][-1].item()):
        raise RuntimeError(f"episode of {question.id} did not end within {max_pushes + 1} steps: is the env's "
                           f"max_pushes larger than {max_pushes}?")
    first, last = traj[0], traj["next"][-1]
    if maps is not None:
        maps.append(object_map(env))
    states = episode_states(traj)
    kept = keeper.choose(states) if keeper is not None else len(states) - 1
    first_map, last_map = (maps[0], maps[-1 if keeper is None else kept]) if maps is not None else (None, None)
    last_answer = _answer_frame(env, last) if kept == len(states) - 1 else states[kept].get(keys.ANSWER_RGB, None)
    kept_state = states[kept]
    scene = env.dataset.scene(question.scene_id)
    scalar = lambda v, dtype=torch.int64: torch.as_tensor(v, dtype=dtype).reshape(())   # noqa: E731
    return TensorDict({
        keys.SLOT: scalar(slot), keys.QUESTION_ID: scalar(question_index), keys.REPEAT: scalar(repeat),
        keys.QUESTION: first.get(keys.QUESTION),
        keys.ANSWER_LABEL: scalar(first.get(keys.ANSWER)),
        keys.TYPE_LABEL: scalar(first.get(keys.QUESTION_TYPE)),
        keys.LEVEL: scalar(LEVELS.index(scene.difficulty)),
        keys.SCENE: scalar(env.dataset.scenes.index(scene)),
        keys.PUSHES: scalar(last.get(keys.PUSH_COUNT)),
        keys.STOPPED: scalar(last.get(keys.IS_STOP), torch.bool),
        keys.EPISODE_TARGETS: first.get(keys.TARGET_MASK),
        keys.CHI_START: _chi(first), keys.CHI_END: _chi(kept_state),
        keys.FIRST: _frame(first, store_depth, first_map, first_answer),
        keys.LAST: _frame(kept_state, store_depth, last_map, last_answer),
    }, batch_size=[])


# ----------------------------------------------------------------------------------------- workers
_WORKER: dict = {}


def _build(dataset_root: str, env_kwargs: dict, spec: dict, run: dict) -> dict:
    env = make_mqa_env(dataset_root, split=None, push_memory=spec.get("push_memory"), **env_kwargs)   # resolved spec
    policy, exploration = make_frozen_policy(spec, env, env_kwargs["max_pushes"])
    keeper = FrameKeeper.from_file(spec["kept_frame"], env.dataset, policy) if spec.get("kept_frame") else None
    return dict(env=env, policy=policy, exploration=exploration, run={**run, "keeper": keeper})


def _episode(state: dict, task: tuple[int, int, int]) -> TensorDict:
    slot, question_index, repeat = task
    return run_question_episode(state["env"], state["policy"], state["exploration"], question_index, slot=slot,
                                repeat=repeat, **state["run"])


def _exit_with_parent(parent: int) -> None:
    while True:
        time.sleep(2.0)
        if os.getppid() != parent:          # the parent died (SIGKILL): nobody will read our results
            os._exit(1)


def _ray_worker_init(dataset_root: str, env_kwargs: dict, spec: dict, run: dict) -> None:
    torch.set_num_threads(1)              # a Ray actor is not our child: Ray ends it with the run
    _WORKER.update(_build(dataset_root, env_kwargs, spec, run))


def _worker_init(dataset_root: str, env_kwargs: dict, spec: dict, run: dict, parent: int) -> None:
    threading.Thread(target=_exit_with_parent, args=(parent,), daemon=True).start()
    _ray_worker_init(dataset_root, env_kwargs, spec, run)


def _worker_episode(task: tuple[int, int, int]) -> dict:
    # numpy, not tensors: torch would pass tensors as shared-memory file descriptors, ~25 per record,
    # and a chunk's worth of records in flight can exceed a 1024 open-files limit
    return _episode(_WORKER, task).numpy()


class _InProcess:
    """The pool's interface in this process (workers ≤ 1): no start-up, easier to debug."""

    def __init__(self, dataset_root: str, env_kwargs: dict, spec: dict, run: dict):
        self.state = _build(dataset_root, env_kwargs, spec, run)

    def imap_unordered(self, fn, tasks, chunksize=1):
        return (_episode(self.state, task) for task in tasks)

    def terminate(self):
        self.state["env"].close()

    def join(self):
        pass


# ----------------------------------------------------------------------------------------- collection
def _answer_camera_held(out_dir, env_kwargs: dict) -> dict:
    """``{"answer_size": n}`` when ``out_dir`` holds a collection of the same env with the answer camera's frames too
    (a counting VQA's rollouts): it serves a VQA that reads the env's frames (vqa=eqa) as it is, so it is resumed so,
    not refused as another plan; else ``{}``."""
    if not (Path(out_dir) / META).is_file():
        return {}
    held = dict(read_meta(out_dir).get("env") or {})
    size = held.pop("answer_size", None)
    held.pop("answer_observation", None)
    return {"answer_size": size} if size is not None and held == env_kwargs else {}


def collect_rollouts(out_dir, *, dataset, policy, split: str, question_types=("counting",), levels=None,
                     max_per_group: int | None = None, repeats: int = 1, max_pushes: int = 10, image_size: int = 224,
                     answer_size: int | None = None, pusher: str = "finger", workers: int = 2, chunk_episodes: int = 32, seed: int = 0,
                     store_depth: bool = True, store_object_map: bool = True, overwrite: bool = False,
                     progress: bool = True, backend: str = "local", ray_address: str | None = None) -> dict:
    """Collect (or finish collecting) the rollouts of ``policy`` (a spec, see ``frozen_policies``) into
    ``out_dir``; returns a summary with the time taken. See the module docstring."""
    if repeats < 1 or chunk_episodes < 1:
        raise ValueError(f"repeats ({repeats}) and chunk_episodes ({chunk_episodes}) must be ≥ 1")
    check_backend(backend, "collection.backend", workers, "collection.workers")
    ds = dataset if isinstance(dataset, MQADataset) else MQADataset(dataset)
    spec = resolve_checkpoint(policy)
    question_types = list(question_types)
    questions = plan_questions(ds, split, question_types, levels, max_per_group, seed)
    if not questions:
        raise ValueError(f"no question of split {split!r}, types {question_types}, levels {levels} in {ds.root}")
    reps = 1 if is_deterministic(spec) else int(repeats)
    tasks = [(i * reps + r, q, r) for i, q in enumerate(questions) for r in range(reps)]
    env_kwargs = {"max_pushes": int(max_pushes), "image_size": int(image_size), "pusher": pusher}
    if answer_size is not None and int(answer_size) != int(image_size):     # absent otherwise: older stores stay resumable
        env_kwargs["answer_size"] = int(answer_size)
    elif not overwrite:
        env_kwargs.update(_answer_camera_held(out_dir, env_kwargs))
    env_kwargs.update(reading_env_options(spec, env_kwargs, ds))     # the counting perception's readers' frames
    run = {"max_pushes": int(max_pushes), "seed": int(seed), "store_depth": bool(store_depth),
           "store_object_map": bool(store_object_map)}
    meta = {"schema": SCHEMA, "kind": "rollouts",
            "dataset": {"root": str(ds.root), "manifest_sha256": dataset_fingerprint(ds.root)},
            "policy": spec, "env": env_kwargs, "stored": {"depth": bool(store_depth), "object_map": bool(store_object_map)},
            "plan": {"split": split, "question_types": question_types, "levels": list(levels or LEVELS),
                     "max_per_group": max_per_group, "repeats": reps, "seed": int(seed),
                     "questions_sha256": questions_sha256(questions)},
            "slots": len(tasks)}
    t0 = time.perf_counter()
    new = pushes = 0
    with EpisodeStore(out_dir, meta, overwrite=overwrite) as store, \
            (ray_session(ray_address, num_cpus=workers) if backend == "ray" else contextlib.nullcontext()):
        done = store.done_slots()
        todo = [t for t in tasks if t[0] not in done]
        build = (str(ds.root), env_kwargs, spec, run)            # what each worker builds its env and policy from
        # a worker costs ~10 s to start (imports, SAPIEN, shader compile): not worth it for a few episodes
        in_process = backend == "local" and (workers <= 1 or len(todo) < IN_PROCESS_BELOW)
        if backend == "ray":
            pool = RayPool(max(1, min(workers, len(todo))), _ray_worker_init, build)
        elif in_process:
            pool = _InProcess(*build)
        else:
            pool = mp.get_context("spawn").Pool(min(workers, len(todo)), initializer=_worker_init,
                                                initargs=(*build, os.getpid()))
        bar = Progress(len(tasks), f"{spec['kind']} {split}", unit="episode", initial=len(done), disable=not progress)
        buffer: list[TensorDict] = []
        try:
            for record in pool.imap_unordered(_worker_episode, todo, chunksize=1):
                record = record if isinstance(record, TensorDict) else TensorDict(record, batch_size=[])
                buffer.append(record)
                new += 1
                pushes += int(record[keys.PUSHES])
                bar.update(1)
                if len(buffer) >= chunk_episodes:
                    store.append(torch.stack(buffer))
                    buffer = []
        finally:
            if buffer:                         # finished episodes are kept even when the run fails
                store.append(torch.stack(buffer))
            pool.terminate()
            pool.join()
            bar.close()
    seconds = time.perf_counter() - t0
    summary = {"out_dir": str(out_dir), "episodes": len(tasks), "collected_now": new, "already_there": len(done),
               "seconds": round(seconds, 1), "episodes_per_s": round(new / seconds, 3) if new else None,
               "pushes_per_s": round(pushes / seconds, 3) if new else None, "workers": workers, "backend": backend}
    with open(Path(out_dir) / "collect_log.jsonl", "a") as f:
        f.write(json.dumps(summary) + "\n")
    return summary


def collect_split(out_dir, split: str, *, dataset, policy, questions, collection, overwrite: bool = False,
                  progress: bool = True, ray_address: str | None = None) -> dict:
    """``collect_rollouts`` from the recipes' config sections: ``questions`` (types, max_per_group per
    split) and ``collection`` (repeats per split, workers, chunk_episodes, seed, store_*, env, backend);
    ``ray_address``: the recipes' ``ray.address``."""
    for section, key in ((collection["repeats"], "collection.repeats"), (questions["max_per_group"], "questions.max_per_group")):
        if split not in section:
            raise ValueError(f"split {split!r}: give {key}.{split}")
    env = collection["env"]
    return collect_rollouts(
        out_dir, dataset=dataset, policy=policy, split=split, question_types=list(questions["types"]),
        max_per_group=questions["max_per_group"][split], repeats=int(collection["repeats"][split]),
        max_pushes=int(env["max_pushes"]), image_size=int(env["image_size"]), answer_size=env.get("answer_size"),
        pusher=env["pusher"],
        workers=int(collection["workers"]), chunk_episodes=int(collection["chunk_episodes"]), seed=int(collection["seed"]),
        store_depth=bool(collection["store_depth"]), store_object_map=bool(collection["store_object_map"]),
        overwrite=overwrite, progress=progress, backend=collection.get("backend", "local"),
        ray_address=ray_address)

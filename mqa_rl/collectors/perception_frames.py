"""Labelled frames for the counting perception, from a pretraining-only dataset of fresh piles.

One *pile episode* rebuilds a scene at its settled rest poses, renders it, then makes
``pushes`` random pushes inside the action mask, rendering after each: the first images every
answering episode starts from and the disturbed piles a policy leaves behind. Every frame becomes
one record of an ``EpisodeStore`` (atomic chunks, resumable, locked; slot = episode × frames + k):

    rgb            uint8 [3, S, S]    the render (``render`` px a side: 224, the env's and the answering
                                      episodes' size, or finer), resized to the perception's input
                                      (antialiased, as ``standardise`` does at answer time)
    depth          float16 [1, S, S]  the depth image (metres), resized alike (``perception.resize_depth``; schema 2)
    object_map     uint8 [S, S]       0 = bin, 1 + the object's slot in the scene (nearest pixel)
    visible_area   float32 [50]       each object's visible pixels in 224-px render units (the counting rule's; a
                                      finer render's count × (224 / render)²)
    object_classes int64 [50]         1 + index into the dataset's classes; 0 = no object in that slot
    scene, level, pushes              which scene, its level, pushes made before this frame

``check_disjoint`` refuses a pretraining dataset that shares a scene with a protected split (the
test split, a held-out evaluation set): learning to see from a scene one is later tested on would
make the test a test of memory.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing as mp
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.rollouts import episode_seed, object_map
from mqa_rl.collectors.frame_records import SCHEMA
from mqa_rl.collectors.store import EpisodeStore
from mqa_rl.data.dataset import LEVELS, MQADataset, dataset_fingerprint
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import MAX_OBJECTS, SapienBinEnv
from mqa_rl.modules.answering.perception import RENDER_SIZE, resize_depth
from mqa_rl.progress import Progress


def scene_fingerprint(scene) -> str:
    """SHA-256 of a scene's objects and rest poses (rounded to 0.1 mm): equal for the same pile."""
    rows = sorted((o.name, *(round(float(v), 4) for v in o.pose)) for o in scene.objects)
    return hashlib.sha256(json.dumps(rows).encode()).hexdigest()


def check_disjoint(pretraining: MQADataset, protected) -> None:
    """``ValueError`` when a scene of ``pretraining`` is one of ``protected``'s ((dataset, split or None) pairs)."""
    mine = {scene_fingerprint(s): s.id for s in pretraining.scenes}
    for ds, split in protected:
        for scene in ds.scenes:
            if (split is None or scene.split == split) and scene_fingerprint(scene) in mine:
                raise ValueError(f"the pretraining dataset {pretraining.root} holds scene {mine[scene_fingerprint(scene)]}, "
                                 f"the same pile as {ds.root}'s {scene.split} scene {scene.id}: frames to learn from "
                                 f"must come from other piles (make_dataset.py with another dataset.seed)")


def resize_rgb(rgb: torch.Tensor, size: int) -> torch.Tensor:
    """uint8 [3, H, W] → uint8 [3, size, size], antialiased bilinear (``standardise``'s resize)."""
    if rgb.shape[-1] == size:
        return rgb
    x = F.interpolate(rgb[None].float(), size=(size, size), mode="bilinear", align_corners=False, antialias=True)
    return x[0].round().clamp(0, 255).to(torch.uint8)


def _frame(env: SapienBinEnv, td, size: int) -> dict:
    omap = object_map(env)
    stride = omap.shape[-1] // size
    to_render_units = (RENDER_SIZE / omap.shape[-1]) ** 2       # a finer render's pixels, counted in 224-px ones
    return {keys.RGB: resize_rgb(td[keys.RGB], size), keys.DEPTH: resize_depth(td[keys.DEPTH][None], size)[0].half(),
            keys.OBJECT_MAP: omap[stride // 2::stride, stride // 2::stride].clone(),
            keys.FRAME_VISIBLE: td[keys.VISIBLE_AREA] * to_render_units, keys.PUSHES: torch.tensor(int(td[keys.PUSH_COUNT]))}


def scene_questions(ds: MQADataset) -> dict[str, str]:
    """{scene id: the id of one of its questions}: what ``env.reset`` takes to rebuild that scene."""
    out: dict[str, str] = {}
    for q in ds.questions:
        out.setdefault(q.scene_id, q.id)
    return out


def pile_episode(env: SapienBinEnv, scene_index: int, question_id: str, *, pushes: int, size: int, seed: int,
                 slot: int) -> TensorDict:
    """Frames [pushes + 1] of one pile episode on the dataset's scene ``scene_index`` (reset through one of its
    questions, ``question_id``; see the module docstring)."""
    ds = env.dataset
    scene = ds.scenes[scene_index]
    rng = torch.Generator().manual_seed(episode_seed(seed, slot))
    td = env.reset(question_id=question_id)
    frames = [_frame(env, td, size)]
    for _ in range(pushes):
        td = env.step(td.set(keys.ACTION, actions.random_push(td[keys.ACTION_MASK], rng)))["next"]
        frames.append(_frame(env, td, size))
    classes = torch.zeros(MAX_OBJECTS, dtype=torch.int64)
    classes[:len(scene.objects)] = torch.tensor([1 + ds.classes.index(o.class_name) for o in scene.objects])
    out = TensorDict({k: torch.stack([f[k] for f in frames]) for k in frames[0]}, batch_size=[len(frames)])
    out.set(keys.OBJECT_CLASSES, classes.expand(len(frames), -1).clone())
    out.set(keys.SCENE, torch.full((len(frames),), scene_index))
    out.set(keys.LEVEL, torch.full((len(frames),), LEVELS.index(scene.difficulty)))
    out.set(keys.SLOT, slot * (pushes + 1) + torch.arange(len(frames)))
    return out


_WORKER: dict = {}


def _init(root: str, render: int, run: dict) -> None:
    torch.set_num_threads(1)
    _WORKER.update(env=SapienBinEnv(root, split=None, max_pushes=max(1, run["pushes"]), image_size=render), run=run)


def _task(task: tuple[int, int, str]) -> dict:
    slot, scene_index, question_id = task
    return pile_episode(_WORKER["env"], scene_index, question_id, slot=slot, **_WORKER["run"]).numpy()


def collect_perception_frames(out_dir, dataset, *, episodes_per_scene: int, pushes: int, size: int = 112,
                              render: int = RENDER_SIZE, protected=(), workers: int = 2, chunk_episodes: int = 16,
                              seed: int = 0, overwrite: bool = False, progress: bool = True) -> dict:
    """Collect (or finish collecting) every scene's ``episodes_per_scene`` pile episodes into ``out_dir``, rendered at
    ``render`` px a side (a finer render than the env's 224 shows thin and small targets a perception cannot resolve
    at 224) and stored at ``size``."""
    if episodes_per_scene < 1 or pushes < 0 or chunk_episodes < 1:
        raise ValueError(f"need episodes_per_scene ≥ 1, pushes ≥ 0, chunk_episodes ≥ 1; got {episodes_per_scene}, "
                         f"{pushes}, {chunk_episodes}")
    if render < RENDER_SIZE or render % RENDER_SIZE or size < 1 or render % size:
        raise ValueError(f"render must be a multiple of {RENDER_SIZE} px and size divide it (frames are the render "
                         f"subsampled); got render={render}, size={size}")
    ds = dataset if isinstance(dataset, MQADataset) else MQADataset(dataset)
    check_disjoint(ds, protected)
    first = scene_questions(ds)
    tasks = [(e * len(ds.scenes) + s, s, first[scene.id]) for e in range(episodes_per_scene) for s, scene in enumerate(ds.scenes)]
    run = {"pushes": int(pushes), "size": int(size), "seed": int(seed)}
    meta = {"schema": SCHEMA, "kind": "perception_frames",
            "dataset": {"root": str(ds.root), "manifest_sha256": dataset_fingerprint(ds.root)},
            "plan": {"episodes_per_scene": int(episodes_per_scene), **run, "render": int(render)},
            "slots": len(tasks) * (pushes + 1)}
    t0 = time.perf_counter()
    new = 0
    with EpisodeStore(out_dir, meta, overwrite=overwrite) as store:
        done = store.done_slots()
        todo = [t for t in tasks if t[0] * (pushes + 1) not in done]
        if workers <= 1:                      # in this process: no worker start-up (~10 s), easier to debug
            _init(str(ds.root), int(render), run)
            pool = None
            results = map(_task, todo)
        else:
            pool = mp.get_context("spawn").Pool(min(workers, max(len(todo), 1)), initializer=_init, initargs=(str(ds.root), int(render), run))
            results = pool.imap_unordered(_task, todo)
        bar = Progress(len(tasks) * (pushes + 1), "frames", unit="frame", initial=len(done), disable=not progress)
        buffer: list[TensorDict] = []
        try:
            for record in results:
                buffer.append(TensorDict(record, batch_size=[pushes + 1]))
                new += pushes + 1
                bar.update(pushes + 1)
                if len(buffer) >= chunk_episodes:
                    store.append(torch.cat(buffer))
                    buffer = []
        finally:
            if buffer:
                store.append(torch.cat(buffer))
            if pool is not None:
                pool.terminate()
                pool.join()
            bar.close()
    seconds = time.perf_counter() - t0
    summary = {"out_dir": str(out_dir), "frames": len(tasks) * (pushes + 1), "collected_now": new,
               "seconds": round(seconds, 1), "frames_per_s": round(new / seconds, 2) if new else None, "workers": workers}
    with open(Path(out_dir) / "collect_log.jsonl", "a") as f:
        f.write(json.dumps(summary) + "\n")
    return summary

"""The VQA's training data, read from an ``EpisodeStore`` of rollouts.

* ``load_answering_records``: the records (question, answer, type, level, scene, ...) with or without
  the two frames' rgb; ``frame_keys`` says which stored frames a VQA reading ``size``-px images takes (the
  answer camera's where the rollouts hold them at that size).
* ``encode_store``: with a frozen encoder, its features of both frames are computed once, chunk by
  chunk from the memmap (the images never all sit in memory), optionally for all 8 dihedral
  transforms of the images: the camera looks straight down on a square bin, so a rotated or
  mirrored image is another plausible scene with the same answers (counting, existence, logic and
  "under" are all invariant); the 70 training scenes are few, and this multiplies them by 8.
* ``scene_split``: a validation set of whole training scenes (stratified by level), for choosing
  the checkpoint without looking at the test split.
* ``Batches``: random minibatches (drawn from the global torch RNG, so a resumed run continues the
  same stream), with a random dihedral transform per sample.
"""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.store import SCENE_OFFSET, chunk_paths, load_records, read_chunk, read_meta
from mqa_rl.data import MQADataset
from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.files import write_atomic
from mqa_rl.modules.answering.vqa import split_repeats
from mqa_rl.envs.dihedral import dihedral, random_dihedral_in

RECORD_KEYS = (keys.QUESTION, keys.ANSWER_LABEL, keys.TYPE_LABEL, keys.LEVEL, keys.SCENE, keys.QUESTION_ID,
               keys.PUSHES, keys.STOPPED, keys.CHI_START, keys.CHI_END)
IMAGE_KEYS = (keys.FIRST_RGB, keys.LAST_RGB)
ANSWER_IMAGE_KEYS = (keys.FIRST_ANSWER_RGB, keys.LAST_ANSWER_RGB)
FEATURE_CACHE = "features"          # under a rollout store: a frozen encoder's features (encode_store's cache_key)


def frame_keys(store: str | Path, size: int | None) -> tuple:
    """The stored (I_start, I_stop) a VQA whose encoder reads ``size``-px images takes: the answer camera's when
    the rollouts hold them at that size (``collection.env.answer_size``), else the env's (resized by the encoder
    when smaller; None: the env's). A finer ``size`` than the store holds is refused: enlarging a 224-px render
    adds no detail (docs/perception.md, "Resolution")."""
    if size is None:
        return IMAGE_KEYS
    env = read_meta(store).get("env", {})
    if env.get("answer_size") == int(size):
        return ANSWER_IMAGE_KEYS
    if int(size) > int(env.get("image_size", size)):
        held = f"{env['image_size']} px" + (f" and {env['answer_size']}-px answer frames" if env.get("answer_size") else "")
        raise ValueError(f"the VQA reads {size}-px frames; the rollouts in {store} hold {held}: collect them with "
                         f"collection.env.answer_size={size} (python recipes/collect.py what=rollouts ... "
                         f"collection.env.answer_size={size} overwrite=true)")
    return IMAGE_KEYS


def load_answering_records(store: str | Path, *, images: bool = True, size: int | None = None,
                           require_complete: bool = True) -> TensorDict:
    """Records [N] of a rollout store, sorted by slot; with ``images`` both frames' rgb (uint8) under
    ``FIRST_RGB`` / ``LAST_RGB``: the frames ``frame_keys(store, size)`` picks."""
    chosen = frame_keys(store, size) if images else ()
    records = load_records(store, (*RECORD_KEYS, *chosen), require_complete=require_complete)
    for key, name in zip(chosen, IMAGE_KEYS):
        if key != name:
            records.rename_key_(key, name)
    return records


def encoder_fingerprint(module: torch.nn.Module) -> str:
    """sha256 of an encoder's settings (its ``config()``, e.g. the perception's counting rule) and weights and
    buffers (names, shapes, values): the key of its cached features."""
    h = hashlib.sha256()
    if callable(getattr(module, "config", None)):
        h.update(json.dumps(module.config(), sort_keys=True, default=str).encode())
    for name, value in sorted(module.state_dict().items()):
        h.update(f"{name}:{tuple(value.shape)}:{value.dtype}".encode())
        h.update(value.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


@torch.no_grad()
def encode_store(store: str | Path, encode, *, transforms: int = 1, batch_size: int = 64, size: int | None = None,
                 cache_key: str | None = None, require_complete: bool = True, progress=None) -> TensorDict:
    """Records [N] with ``FIRST_FEATURES`` / ``LAST_FEATURES`` [N, transforms, C, h, w] (float16) computed
    by ``encode`` (uint8 [B, 3, H, W] → [B, C, h, w], e.g. ``VQAModel.encode_frames`` in eval mode) for
    the first ``transforms`` dihedral transforms of each frame (the frames ``frame_keys(store, size)`` picks).

    ``cache_key`` (e.g. ``encoder_fingerprint`` of a frozen encoder): the features are kept in
    ``<store>/features/`` and read back by the next call with the same key, frames and records (a head's
    seeds share one pass of a perception that reads 448-px frames at ~6 frames/s on 2 cores). Identical
    images (by digest) are encoded once: a scene's I_start recurs in each of its episodes."""
    records = load_answering_records(store, images=False, require_complete=require_complete)
    chosen = frame_keys(store, size)
    cache = Path(store) / FEATURE_CACHE / f"{cache_key[:16]}-{'-'.join(chosen[0])}-t{transforms}.pt" if cache_key else None
    if cache is not None and cache.exists():
        try:
            saved = torch.load(cache, weights_only=True)
        except Exception:                  # noqa: BLE001 - an unreadable cache is recomputed and replaced
            saved = {}
        if saved.get("key") == cache_key and torch.equal(saved["slots"], records.get(keys.SLOT)):
            records.set(keys.FIRST_FEATURES, saved["first"])
            records.set(keys.LAST_FEATURES, saved["last"])
            if progress is not None:
                progress.update(2 * len(records))
            return records
    order = {int(s): i for i, s in enumerate(records.get(keys.SLOT))}
    feats = {key: None for key in IMAGE_KEYS}
    seen: dict[bytes, tuple[str, int]] = {}    # an image's digest → where its features are
    for path in chunk_paths(store):
        chunk = read_chunk(path)
        rows = torch.tensor([order[int(s)] for s in chunk.get(keys.SLOT)])
        for key, stored in zip(IMAGE_KEYS, chosen):
            images = chunk.get(stored)
            fresh, copies = split_repeats(images, seen, lambda i: (key, int(rows[i])))
            fresh = torch.tensor(fresh, dtype=torch.long)
            for start in range(0, len(fresh), batch_size):
                take = fresh[start:start + batch_size]
                block = images[take].clone()
                per_t = [encode(dihedral(block, k)).to(torch.float16) for k in range(transforms)]
                out = torch.stack(per_t, 1)                                 # [b, T, C, h, w]
                if feats[key] is None:
                    feats = {k: torch.zeros(len(records), *out.shape[1:], dtype=torch.float16) for k in IMAGE_KEYS}
                feats[key][rows[take]] = out
            for i, (src_key, src_row) in copies:
                feats[key][rows[i]] = feats[src_key][src_row]
            if progress is not None:
                progress.update(images.shape[0])
    if feats[IMAGE_KEYS[0]] is None:
        raise ValueError(f"{store} holds no images")
    records.set(keys.FIRST_FEATURES, feats[keys.FIRST_RGB])
    records.set(keys.LAST_FEATURES, feats[keys.LAST_RGB])
    if cache is not None:
        buffer = io.BytesIO()
        torch.save({"key": cache_key, "slots": records.get(keys.SLOT), "first": feats[keys.FIRST_RGB],
                    "last": feats[keys.LAST_RGB]}, buffer)
        write_atomic(cache, buffer.getvalue())
    return records


def question_class_labels(records: TensorDict, dataset: MQADataset) -> torch.Tensor:
    """int64 [N, 2]: the classes each record's question names (``QUESTION_CLASSES``: 1 + index into
    ``dataset.classes``, the encoder's class channels; −1 where it names fewer), for the grounding loss."""
    labels = torch.full((records.shape[0], 2), -1, dtype=torch.int64)
    for i, q in enumerate(records.get(keys.QUESTION_ID).tolist()):
        named = dataset.questions[int(q)].classes[:2]
        labels[i, :len(named)] = torch.tensor([1 + dataset.classes.index(c) for c in named])
    return labels


def scene_split(records: TensorDict, val_fraction: float, seed: int = 0) -> torch.Tensor:
    """Bool [N]: the records whose scene is held out for validation (≈ ``val_fraction`` of each level's
    scenes, at least one where a level has two or more; none when ``val_fraction`` is 0)."""
    val = torch.zeros(records.shape[0], dtype=torch.bool)
    if val_fraction <= 0:
        return val
    scenes, levels = records.get(keys.SCENE), records.get(keys.LEVEL)
    rng = np.random.default_rng(seed)
    for level in levels.unique().tolist():
        ids = sorted(scenes[levels == level].unique().tolist())
        n = int(round(val_fraction * len(ids)))
        n = max(n, 1) if len(ids) > 1 else 0
        held = rng.choice(ids, size=n, replace=False).tolist() if n else []
        val |= torch.isin(scenes, torch.tensor(held, dtype=scenes.dtype))
    return val


class Batches:
    """Random minibatches of ``records`` (features or images), each sample under a random dihedral
    transform when ``augment`` (features: one of the cached transforms)."""

    def __init__(self, records: TensorDict, batch_size: int, *, augment: bool):
        self.records = records
        self.batch_size = int(batch_size)
        self.augment = augment
        self.features = keys.FIRST_FEATURES in records.keys(True)

    def __len__(self) -> int:
        return self.records.shape[0]

    def sample(self) -> TensorDict:
        idx = torch.randint(len(self), (self.batch_size,))
        return self.take(idx, augment=self.augment)

    def take(self, idx: torch.Tensor, augment: bool = False) -> TensorDict:
        batch = self.records[idx]
        if self.features:
            first, last = batch.get(keys.FIRST_FEATURES), batch.get(keys.LAST_FEATURES)
            t = torch.randint(first.shape[1], (len(idx),)) if augment else torch.zeros(len(idx), dtype=torch.int64)
            rows = torch.arange(len(idx))
            batch.set(keys.FIRST_FEATURES, first[rows, t].float())
            batch.set(keys.LAST_FEATURES, last[rows, t].float())
        elif augment:
            random_dihedral_in(batch, IMAGE_KEYS)
        return batch

    def all(self, batch_size: int):
        """The records in order, in batches, without augmentation (validation)."""
        for start in range(0, len(self), batch_size):
            yield self.take(torch.arange(start, min(start + batch_size, len(self))))




def store_dataset(store: str | Path, dataset, loaded: dict | None = None):
    """The ``MQADataset`` a rollout store was collected on: ``dataset`` itself, or the one its meta names
    (checked by fingerprint, and it must have ``dataset``'s classes: the class labels index them).
    ``loaded`` ({fingerprint: dataset}) keeps datasets already read: a 1,000-scene one takes seconds."""
    info = read_meta(store).get("dataset", {})
    loaded = {dataset_fingerprint(dataset.root): dataset} if loaded is None else loaded
    if info.get("manifest_sha256") is None:
        return dataset
    if info["manifest_sha256"] in loaded:
        return loaded[info["manifest_sha256"]]
    root = Path(info.get("root", ""))
    if not (root / "manifest.json").is_file() or dataset_fingerprint(root) != info["manifest_sha256"]:
        raise ValueError(f"{store} was collected on the dataset {info.get('root')!r}, which is not there (or has "
                         f"changed since): make it again with the same make_dataset.py command, or drop that store")
    other = MQADataset(root)
    if list(other.classes) != list(dataset.classes):
        raise ValueError(f"{store} was collected on {root}, whose classes differ from {dataset.root}'s: its class "
                         f"labels would mean other objects; pretrain on stores of datasets with the same object library")
    loaded[info["manifest_sha256"]] = other
    return other


def pretraining_frames(stores, dataset, *, max_frames: int | None = None, seed: int = 0) -> TensorDict:
    """Frames [N] (``RGB``, ``DEPTH``, ``OBJECT_MAP``, ``CLASS_MAP``, ``SCENE``, ``LEVEL``) for pretraining the
    encoder, from rollout stores collected with depth and object maps: each scene's first image once (it
    is the same for every question of the scene) and every last image after at least one push; at most
    ``max_frames`` of them, drawn with ``seed``. ``dataset`` is the ``MQADataset`` the VQA answers on
    (its classes label the frames); a store collected on another dataset of the same objects (more
    scenes to learn to see from: ``make_dataset.py dataset.seed=1 dataset.out_dir=...``) is read with
    that one, its scene ids offset by ``SCENE_OFFSET`` per extra dataset so that scenes stay distinct."""
    wanted = (keys.RGB, keys.DEPTH, keys.OBJECT_MAP)
    picks = []                                       # (chunk path, frame, row, scene, level, dataset, scene offset)
    seen_scenes = set()
    loaded = {dataset_fingerprint(dataset.root): dataset}
    offsets = {fingerprint: 0 for fingerprint in loaded}
    for store in stores:
        meta = read_meta(store)
        if not (meta.get("stored", {}).get("depth") and meta.get("stored", {}).get("object_map")):
            raise ValueError(f"{store} was collected without depth or object maps (collection.store_depth / "
                             f"store_object_map false): pretraining needs both")
        ds = store_dataset(store, dataset, loaded)
        fingerprint = next(f for f, d in loaded.items() if d is ds)
        offset = offsets.setdefault(fingerprint, len(offsets) * SCENE_OFFSET)
        for path in chunk_paths(store):
            chunk = read_chunk(path)
            scenes, levels = chunk.get(keys.SCENE).tolist(), chunk.get(keys.LEVEL).tolist()
            for row, (scene, level, n) in enumerate(zip(scenes, levels, chunk.get(keys.PUSHES).tolist())):
                if (offset, scene) not in seen_scenes:
                    seen_scenes.add((offset, scene))
                    picks.append((path, keys.FIRST, row, scene, level, ds, offset))
                if n > 0:
                    picks.append((path, keys.LAST, row, scene, level, ds, offset))
    if not picks:
        raise ValueError(f"no frames in {list(stores)}: collect rollouts first (recipes/collect.py what=rollouts)")
    if max_frames is not None and len(picks) > max_frames:
        keep = np.random.default_rng(seed).choice(len(picks), size=max_frames, replace=False)
        picks = [picks[i] for i in sorted(keep)]
    frames, cache = [], {}
    for path, which, row, scene, level, ds, offset in picks:
        if path not in cache:
            cache.clear()
            cache[path] = read_chunk(path)
        frame = cache[path].get(which)[row].select(*wanted).clone()
        objects = ds.scenes[scene].objects
        lut = torch.zeros(256, dtype=torch.uint8)
        lut[1:len(objects) + 1] = torch.tensor([1 + ds.classes.index(o.class_name) for o in objects], dtype=torch.uint8)
        frame.set(keys.CLASS_MAP, lut[frame.get(keys.OBJECT_MAP).long()])
        frame.set(keys.SCENE, torch.tensor(offset + scene))
        frame.set(keys.LEVEL, torch.tensor(level))
        frames.append(frame)
    return torch.stack(frames)

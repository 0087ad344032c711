"""A frame pack: the encoder's pretraining frames in one self-describing, lossless, compressed file.

Rendering needs the simulator (CPU); pretraining wants a GPU. A pack carries the frames from one
machine to the other: ``recipes/pretrain.py part=vqa_encoder export_pack=frames.xz`` writes it from the
rollout stores, ``frames.pack=frames.xz`` trains from it on a machine that has neither the stores nor
the dataset (the pack holds what the recipe reads from them: the classes, the camera distance and
the dataset's fingerprint). ~21 kB per frame (xz over rgb uint8, depth float16, object and class
maps), against ~0.58 MB per rollout episode in a store.
"""

from __future__ import annotations

import io
import json
import lzma
import zipfile
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.files import write_atomic

FORMAT = "mqa_rl.frame_pack/1"
PACK_KEYS = (keys.RGB, keys.DEPTH, keys.OBJECT_MAP, keys.CLASS_MAP, keys.SCENE, keys.LEVEL)
META_KEYS = ("classes", "camera_distance", "dataset_sha256", "stores")


def save_frame_pack(frames: TensorDict, path: str | Path, meta: dict, preset: int = 6) -> Path:
    """Write ``frames`` ([N] with ``PACK_KEYS``, as ``pretraining_frames`` returns them) and ``meta`` (with
    ``META_KEYS``) to ``path`` atomically."""
    missing = [k for k in META_KEYS if k not in meta] + [k for k in PACK_KEYS if k not in frames.keys()]
    if missing:
        raise ValueError(f"a frame pack needs {missing}")
    buffer = io.BytesIO()
    arrays = {k: frames.get(k).numpy() for k in PACK_KEYS}
    np.savez(buffer, meta=np.array(json.dumps({"format": FORMAT, **meta})), **arrays)
    return write_atomic(Path(path), lzma.compress(buffer.getvalue(), preset=preset))


def load_frame_pack(path: str | Path) -> tuple[TensorDict, dict]:
    """(frames [N], meta) of a pack written by ``save_frame_pack``; a clear error for anything else."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no frame pack at {path}: write one with `python recipes/pretrain.py part=vqa_encoder "
                                f"export_pack={path}` where the rollouts are")
    try:
        with np.load(io.BytesIO(lzma.decompress(path.read_bytes())), allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("format") != FORMAT:
                raise ValueError(f"format {meta.get('format')!r}, expected {FORMAT!r}")
            arrays = {k: torch.from_numpy(z[k]) for k in PACK_KEYS}
    except (lzma.LZMAError, zipfile.BadZipFile, EOFError, OSError, KeyError, ValueError) as err:
        raise ValueError(f"{path} is not a readable frame pack ({err}): write it again with "
                         f"`python recipes/pretrain.py part=vqa_encoder export_pack={path}`") from err
    n = arrays[keys.RGB].shape[0]
    return TensorDict(arrays, batch_size=[n]), meta

"""The versioned on-disk dataset format and its atomic writer.

Layout (every file but ``manifest.json`` is listed in the manifest with its SHA-256)::

    manifest.json        schema_version, generator, seed, config, counts, files {path: sha256}
    objects.json         the object library: class, instance, density, mass, dimensions, folder
    objects/<class>/<instance>/visual_XX.ply, collision_XX.ply
    scenes.json          id, difficulty, split, objects [{class, instance, pose}]
    questions.jsonl      one question per line: id, scene_id, type, text, tokens, classes, answer
    vocab.json           question vocabulary (itos) and answer vocabulary
    stats.json           answer statistics (the paper's Fig. 4)

Writes go to a hidden sibling folder that is renamed into place only once complete, so an
interrupted generation never leaves a folder that loads. Files contain no timestamps: the same seed
gives the same bytes.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import uuid
from pathlib import Path

SCHEMA_VERSION = 1
MANIFEST = "manifest.json"


class DatasetError(ValueError):
    """A dataset folder that is missing, partial, corrupt or of another schema version."""


def dumps_json(obj) -> bytes:
    """Canonical JSON bytes (sorted keys, fixed separators): deterministic across runs."""
    return (json.dumps(obj, sort_keys=True, indent=1, ensure_ascii=False) + "\n").encode()


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def write_dataset_atomically(out_dir: Path, files: dict[str, bytes], manifest: dict, overwrite: bool = False) -> Path:
    """Write ``files`` (relative path → bytes) and a manifest listing their checksums into ``out_dir``."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not overwrite:
        raise FileExistsError(f"{out_dir} already exists; pass overwrite=True (or choose another folder)")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_dir.parent / f".{out_dir.name}.tmp-{uuid.uuid4().hex[:8]}"
    try:
        tmp.mkdir()
        for rel, data in files.items():
            path = tmp / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        manifest = dict(manifest, schema_version=SCHEMA_VERSION, files={rel: sha256(d) for rel, d in sorted(files.items())})
        (tmp / MANIFEST).write_bytes(dumps_json(manifest))     # last: a folder without it never loads
        if out_dir.exists():
            old = out_dir.parent / f".{out_dir.name}.old-{uuid.uuid4().hex[:8]}"
            os.rename(out_dir, old)
            os.rename(tmp, out_dir)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir


def read_verified(root: Path) -> tuple[dict, dict[str, bytes]]:
    """The manifest and the bytes of every file it lists, after checking version and checksums."""
    root = Path(root)
    hint = f"regenerate it with `python recipes/make_dataset.py dataset.out_dir={root}`"
    mpath = root / MANIFEST
    if not root.is_dir():
        raise DatasetError(f"no dataset at {root}: the folder does not exist; {hint}")
    if not mpath.is_file():
        raise DatasetError(f"{root} is not a complete mqa_rl dataset (no {MANIFEST}); {hint}")
    try:
        manifest = json.loads(mpath.read_bytes())
        version = int(manifest["schema_version"])
        listed = dict(manifest["files"])
    except (ValueError, KeyError, TypeError) as e:
        raise DatasetError(f"{mpath} is corrupt ({e}); {hint}") from None
    if version > SCHEMA_VERSION:
        raise DatasetError(
            f"{root} uses dataset schema {version}, newer than this mqa_rl supports ({SCHEMA_VERSION}); upgrade mqa_rl"
        )
    if version < SCHEMA_VERSION:
        raise DatasetError(f"{root} uses the old dataset schema {version} (current {SCHEMA_VERSION}); {hint}")
    data = {}
    for rel, digest in listed.items():
        path = root / rel
        if not path.is_file():
            raise DatasetError(f"{root} is incomplete: {rel} is missing; {hint}")
        blob = path.read_bytes()
        if sha256(blob) != digest:
            raise DatasetError(f"{root} is corrupt: {rel} does not match its checksum; {hint}")
        data[rel] = blob
    return manifest, data

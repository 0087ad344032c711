"""The versioned on-disk dataset format and its atomic writer.

Layout (every file but ``manifest.json`` is listed in the manifest with its SHA-256)::

    manifest.json        schema_version, generator, seed, config, counts, files {path: sha256}
    objects.json         the object library: class, instance, density, mass, dimensions, folder
    objects/<class>/<instance>/visual_XX.ply, collision_XX.ply
    scenes.json          id, difficulty, split, objects [{class, instance, pose}]
    questions.jsonl      one question per line: id, scene_id, type, text, tokens, classes, answer
    vocab.json           question vocabulary (itos) and answer vocabulary
    stats.json           answer statistics (the paper's Fig. 4)

Writes go to a hidden sibling folder (``.NAME.tmp-<pid>-<id>``) that is renamed into place only once
complete, so an interrupted generation never leaves a folder that loads. An overwrite moves the old
dataset aside (``.NAME.old-<pid>-<id>``) for the instant between two renames. A process killed
mid-way leaves these behind: the loader and the next generation notice them (``recover_leftovers``),
restore an old dataset whose replacement never arrived, remove the rest, and say so with a warning.
Files contain no timestamps: the same seed gives the same bytes.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import uuid
import warnings
from pathlib import Path

SCHEMA_VERSION = 2    # 2: real-size objects, piled scenes, 40 × 40 × 45 cm bin, camera framing the rim
MANIFEST = "manifest.json"


class DatasetError(ValueError):
    """A dataset folder that is missing, partial, corrupt or of another schema version."""


def dumps_json(obj) -> bytes:
    """Canonical JSON bytes (sorted keys, fixed separators): deterministic across runs."""
    return (json.dumps(obj, sort_keys=True, indent=1, ensure_ascii=False) + "\n").encode()


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _hidden_sibling(out_dir: Path, tag: str) -> Path:
    return out_dir.parent / f".{out_dir.name}.{tag}-{os.getpid()}-{uuid.uuid4().hex[:8]}"


def _writer_alive(path: Path) -> bool:
    """Whether the process named in a hidden sibling's name still runs (then it is no leftover)."""
    parts = path.name.rsplit("-", 2)
    if len(parts) != 3 or not parts[1].isdigit() or int(parts[1]) == os.getpid():
        return False
    try:
        os.kill(int(parts[1]), 0)
    except ProcessLookupError:
        return False
    except OSError:             # exists, owned by someone else
        return True
    return True


def _leftovers(out_dir: Path, tag: str) -> list[Path]:
    prefix = f".{out_dir.name}.{tag}-"
    if not out_dir.parent.is_dir():
        return []
    found = [p for p in out_dir.parent.iterdir() if p.name.startswith(prefix) and p.is_dir()]
    return sorted((p for p in found if not _writer_alive(p)), key=lambda p: p.stat().st_mtime)


def _remove(path: Path, why: str) -> None:
    try:
        shutil.rmtree(path)
        warnings.warn(f"removed {path}: {why}", stacklevel=3)
    except OSError as e:
        warnings.warn(f"could not remove {path} ({why}): {e}; delete it by hand", stacklevel=3)


def recover_leftovers(out_dir) -> None:
    """Undo what a killed ``write_dataset_atomically`` left next to ``out_dir``, with a warning each.

    A ``.NAME.old-*`` folder while ``NAME`` is missing is the previous dataset of an overwrite killed
    between its two renames: it is renamed back. Other ``.old-*`` and every ``.tmp-*`` (unfinished
    writes) are removed. Folders of a writer that is still running are left alone.
    """
    out_dir = Path(out_dir)
    olds = _leftovers(out_dir, "old")
    if olds and not out_dir.exists():
        newest = olds.pop()
        os.rename(newest, out_dir)
        warnings.warn(f"restored {out_dir} from {newest.name}, left by an overwrite that was interrupted "
                      f"before the new dataset was moved into place", stacklevel=2)
    for old in olds:
        _remove(old, "the previous dataset of an overwrite that was interrupted while deleting it")
    for tmp in _leftovers(out_dir, "tmp"):
        _remove(tmp, "an unfinished dataset write that was interrupted (it never became a dataset)")


def check_out_dir(out_dir, overwrite: bool) -> Path:
    """Recover leftovers, then refuse an ``out_dir`` that must not be written: before any work is done."""
    out_dir = Path(out_dir)
    recover_leftovers(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise FileExistsError(f"{out_dir} is a file, not a dataset folder; choose another path")
    if out_dir.exists() and not overwrite:
        raise FileExistsError(f"{out_dir} already exists; pass overwrite=True (or choose another folder)")
    if out_dir.exists() and not (out_dir / MANIFEST).is_file() and any(out_dir.iterdir()):
        raise FileExistsError(f"{out_dir} is not an mqa_rl dataset (no {MANIFEST}) and not empty: refusing to "
                              f"replace it with overwrite=True; choose another folder or empty it yourself")
    return out_dir


def write_dataset_atomically(out_dir: Path, files: dict[str, bytes], manifest: dict, overwrite: bool = False) -> Path:
    """Write ``files`` (relative path → bytes) and a manifest listing their checksums into ``out_dir``."""
    out_dir = check_out_dir(out_dir, overwrite)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = _hidden_sibling(out_dir, "tmp")
    try:
        tmp.mkdir()
        for rel, data in files.items():
            path = tmp / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        manifest = dict(manifest, schema_version=SCHEMA_VERSION, files={rel: sha256(d) for rel, d in sorted(files.items())})
        (tmp / MANIFEST).write_bytes(dumps_json(manifest))     # last: a folder without it never loads
        if out_dir.exists():
            old = _hidden_sibling(out_dir, "old")
            os.rename(out_dir, old)
            try:
                os.rename(tmp, out_dir)
            except BaseException:
                os.rename(old, out_dir)                        # put the previous dataset back
                raise
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
    hint = (f"make or regenerate it with `python recipes/make_dataset.py dataset.out_dir={root} dataset.seed=<its seed>` (the default "
            f"seed 0 makes data/mqa's piles: a held-out or pretraining set needs a seed of its own, e.g. the one its "
            f"config's comment names)")
    mpath = root / MANIFEST
    recover_leftovers(root)
    if root.exists() and not root.is_dir():
        raise DatasetError(f"{root} is a file, not a dataset folder; pass the folder generate_dataset wrote")
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

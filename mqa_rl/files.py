"""Files written whole or not at all, and small tagged model files: the bottom of the house (imports
nothing else from mqa_rl).

``write_atomic`` writes through a hidden temporary sibling and a rename, so a reader (or a run killed
mid-write) never sees half a file. ``save_versioned`` / ``load_versioned``: a dict tagged with its
format and version, written atomically, read with errors that say what to do (missing, unreadable or
truncated, foreign, newer than this mqa_rl); used by the push recognition file, the stop critic and
the perception. Training checkpoints use ``torchrl.checkpoint`` (``mqa_rl.verified_checkpoint``).

Importing this module does not import torch (the report writers use ``write_atomic``).
"""

from __future__ import annotations

import io
import os
from pathlib import Path


def write_atomic(path: Path, text: str | bytes) -> Path:
    """``text`` (str: UTF-8) to ``path``, its folder made if missing, through a temporary file and a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_bytes(text if isinstance(text, bytes) else text.encode())
    os.replace(tmp, path)
    return path


def load_failure(error: Exception) -> str:
    """Why ``torch.load(..., weights_only=True)`` refused a file, in words for a user: never torch's own
    advice to retry with ``weights_only=False`` (which would run whatever code the file holds)."""
    text = str(error)
    if "Unsupported global" in text:
        return "it holds pickled Python objects besides tensors, which are never unpickled here"
    if "Weights only" in text or "weights_only" in text:
        return "it is not a file of tensors and plain containers"
    return f"{type(error).__name__}: {text.splitlines()[0][:200] if text else ''}"


def load_tensors(path: str | Path, *, what: str, hint: str):
    """A file of tensors and plain containers (``torch.save`` of dicts, lists, numbers, strings) read with
    ``weights_only=True``: a file holding pickled objects is refused with ``ValueError`` naming it, never
    unpickled (a crafted cache or results file in a folder a user was handed would run its code)."""
    import torch

    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:
        raise ValueError(f"{path} is not a readable {what} ({load_failure(error)}): {hint}") from error


def refuse_nonfinite(state_dict, path, hint: str) -> None:
    """ValueError naming the weights of a model file that hold NaN or infinity: loaded, they answer or count nonsense
    silently (a crafted or damaged file)."""
    import torch

    bad = [k for k, v in (state_dict or {}).items() if torch.is_tensor(v) and v.is_floating_point()
           and not torch.isfinite(v).all()]
    if bad:
        raise ValueError(f"{path}: the weights {bad[:3]} hold NaN or infinity; {hint}")


PICKLED = ("*.pickle", "*.pkl")      # what TensorDict and TorchRL write for objects that are not tensors


class PickledFileRefused(ValueError):
    """A folder a recipe reads holds a pickle, which is never unpickled here (unpickling runs its code)."""


def refuse_pickles(folder: str | Path, *, what: str, hint: str) -> None:
    """``PickledFileRefused`` naming the first pickled file anywhere under ``folder``: mqa_rl writes tensors and
    JSON only, so a pickle in a rollout chunk, a checkpoint or a replay buffer was put there by someone else."""
    folder = Path(folder)
    found = sorted(f for pattern in PICKLED for f in folder.rglob(pattern)) if folder.is_dir() else []
    if found:
        raise PickledFileRefused(f"{what} {folder} holds a pickled file, {found[0]}, which is never unpickled here "
                                 f"(it could run any code): mqa_rl writes tensors and JSON only; {hint}")


class TruncatedFile(ValueError):
    """A memmap file shorter (or longer) than its ``meta.json`` says: mapped as it is, its missing bytes would read
    as zeros (an interrupted copy, a full disk)."""


def check_memmap_sizes(folder: str | Path, *, what: str, hint: str) -> None:
    """Every tensor file under a ``TensorDict.memmap`` folder holds the bytes its ``meta.json`` shape and dtype
    need; an unreadable or missing ``meta.json`` is named too. Raises ``TruncatedFile`` / ``ValueError``."""
    import json
    import math

    import torch

    folder = Path(folder)
    if not (folder / "meta.json").is_file():
        raise ValueError(f"{what} {folder} has no meta.json (an empty or half-copied folder): {hint}")
    for meta_path in sorted(folder.rglob("meta.json")):
        try:
            meta = json.loads(meta_path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
            raise ValueError(f"{what}: {meta_path} is not readable JSON ({type(error).__name__}: {error}): {hint}") from None
        for key, entry in meta.items():
            if not (isinstance(entry, dict) and "shape" in entry and "dtype" in entry) or entry.get("is_nested"):
                continue
            dtype = getattr(torch, str(entry["dtype"]).removeprefix("torch."), None)
            if not isinstance(dtype, torch.dtype):
                raise ValueError(f"{what}: {meta_path} names an unknown dtype {entry['dtype']!r} for {key}: {hint}")
            need = math.prod(int(n) for n in entry["shape"]) * torch.empty((), dtype=dtype).element_size()
            data = meta_path.parent / f"{key}.memmap"
            have = data.stat().st_size if data.is_file() else None
            if have is None and need:
                raise TruncatedFile(f"{what}: {data} is missing ({need} bytes expected by {meta_path}): {hint}")
            if have is not None and have != need:
                raise TruncatedFile(f"{what}: {data} holds {have} bytes where {meta_path} expects {need} "
                                    f"({list(entry['shape'])} × {entry['dtype']}; a truncated copy?): {hint}")


def load_memmap(path: str | Path, *, what: str, hint: str):
    """``TensorDict.load_memmap(path)`` of tensors and JSON only, each file the size its ``meta.json`` says: a pickled
    leaf (``other.pickle``) is refused with ``PickledFileRefused`` naming the file, a short file with
    ``TruncatedFile``, before anything is read."""
    from tensordict import TensorDict

    refuse_pickles(path, what=what, hint=hint)
    check_memmap_sizes(path, what=what, hint=hint)
    return TensorDict.load_memmap(path, allow_pickle=False)


def save_versioned(path: str | Path, fmt: str, version: int, blob: dict) -> Path:
    """``blob`` with ``format`` and ``version`` to ``path``, through a temporary file and a rename."""
    import torch

    buffer = io.BytesIO()
    torch.save({"format": fmt, "version": int(version), **blob}, buffer)
    return write_atomic(Path(path), buffer.getvalue())


def load_versioned(path: str | Path, fmt: str, version: int, *, what: str, hint: str) -> dict:
    """The dict saved at ``path`` by ``save_versioned(path, fmt, ...)``; FileNotFoundError or ValueError
    naming ``what`` the file should be and ``hint`` (how to make one)."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no {what} at {path}: {hint}")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:
        raise ValueError(f"{path} cannot be read ({load_failure(error)}); it may be truncated: {hint}") from error
    if not isinstance(blob, dict) or blob.get("format") != fmt:
        raise ValueError(f"{path} is not a {what}; {hint}")
    if int(blob.get("version", 0)) > version:
        raise ValueError(f"{path} has format version {blob['version']} > {version}: update mqa_rl")
    return blob

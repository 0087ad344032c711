"""A small model file: a dict tagged with its format and version, written atomically, read with errors
that say what to do (missing, unreadable or truncated, foreign, newer than this mqa_rl).

Used by the push recognition file and the stop critic; training checkpoints use ``torchrl.checkpoint``.
"""

from __future__ import annotations

import os
from pathlib import Path

import torch


def save_versioned(path: str | Path, fmt: str, version: int, blob: dict) -> Path:
    """``blob`` with ``format`` and ``version`` to ``path``, through a temporary file and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    torch.save({"format": fmt, "version": int(version), **blob}, tmp)
    os.replace(tmp, path)
    return path


def load_versioned(path: str | Path, fmt: str, version: int, *, what: str, hint: str) -> dict:
    """The dict saved at ``path`` by ``save_versioned(path, fmt, ...)``; FileNotFoundError or ValueError
    naming ``what`` the file should be and ``hint`` (how to make one)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no {what} at {path}: {hint}")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:
        raise ValueError(f"{path} cannot be read ({type(error).__name__}: {error}); it may be truncated: {hint}") from error
    if not isinstance(blob, dict) or blob.get("format") != fmt:
        raise ValueError(f"{path} is not a {what}; {hint}")
    if int(blob.get("version", 0)) > version:
        raise ValueError(f"{path} has format version {blob['version']} > {version}: update mqa_rl")
    return blob

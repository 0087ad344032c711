"""A small model file: a dict tagged with its format and version, written atomically, read with errors
that say what to do (missing, unreadable or truncated, foreign, newer than this mqa_rl).

Used by the push recognition file and the stop critic; training checkpoints use ``torchrl.checkpoint``.
"""

from __future__ import annotations

import io
from pathlib import Path

import torch

from mqa_rl.evaluation.answering_report import write_atomic


def save_versioned(path: str | Path, fmt: str, version: int, blob: dict) -> Path:
    """``blob`` with ``format`` and ``version`` to ``path``, through a temporary file and a rename."""
    buffer = io.BytesIO()
    torch.save({"format": fmt, "version": int(version), **blob}, buffer)
    return write_atomic(Path(path), buffer.getvalue())


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

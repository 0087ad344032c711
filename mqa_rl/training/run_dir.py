"""A training recipe's ``out_dir``: one writer at a time, sizes checked before anything is written, and
no new run started beside the logs of a run that died before its first checkpoint (its rows and its
``config.yaml`` would be mixed with the new run's)."""

from __future__ import annotations

import fcntl
import numbers
import shutil
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

LOCK_NAME = ".lock"
RUN_FILES = ("config.yaml", "csv", "summary.json")


def positive_ints(cfg: DictConfig, *names: str, minimum: int = 1) -> None:
    """Raise ``ValueError`` naming the first dotted key of ``cfg`` that is not an integer ≥ ``minimum`` (a
    bool, 7.5, NaN, 0 and -8 are refused), before a recipe writes or computes anything."""
    for name in names:
        value = OmegaConf.select(cfg, name)
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
            raise ValueError(f"{name}={value!r} must be " + ("a positive integer" if minimum == 1
                                                              else f"a whole number ≥ {minimum}"))


class RunLock:
    """An exclusive ``flock`` on ``out_dir/.lock`` while a run writes there: a second run in the same
    folder is refused at once instead of doubling every log row and overwriting checkpoints. The
    kernel drops the lock when the process dies, so a killed run never blocks its resume. A folder the
    lock made and the run left empty (refused before writing anything) goes again. Once the lock is held, the
    half-written checkpoints a run killed mid-save left (``checkpoints/.<name>.stage-<id>``: TorchRL publishes a
    checkpoint by renaming its stage, ~1.5 GB with the default replay) are removed: no writer can own them."""

    def __init__(self, out_dir: str | Path, recipe: str):
        self.path = Path(out_dir) / LOCK_NAME
        self.recipe = recipe
        self._file = None
        self._made_folder = False

    def __enter__(self) -> "RunLock":
        if self.path.parent.exists() and not self.path.parent.is_dir():
            raise NotADirectoryError(f"out_dir={self.path.parent} is a file: choose a folder")
        self._made_folder = not self.path.parent.exists()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "w")
        try:
            fcntl.flock(self._file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._file.close()
            raise RuntimeError(f"another {self.recipe} run is writing to {self.path.parent}: wait for it to finish, "
                               f"or choose another out_dir") from None
        for stage in sorted((self.path.parent / "checkpoints").glob(".*.stage-*")):
            print(f"removing {stage}, a checkpoint left half-written by a run killed while saving it", flush=True)
            shutil.rmtree(stage) if stage.is_dir() else stage.unlink()
        return self

    def __exit__(self, *exc) -> None:
        folder = self.path.parent
        if self._made_folder and folder.is_dir() and [p.name for p in folder.iterdir()] == [LOCK_NAME]:
            self.path.unlink()
            folder.rmdir()
        fcntl.flock(self._file, fcntl.LOCK_UN)
        self._file.close()


def refuse_unresumable(out_dir: str | Path, has_checkpoint: bool, resume: bool) -> None:
    """The folder rules shared by the training recipes: a folder with checkpoints needs ``resume=true``;
    a folder with a run's files but no checkpoint (killed before its first one, or another recipe's
    results) is refused either way, naming what to do."""
    out = Path(out_dir)
    if has_checkpoint:
        if not resume:
            raise FileExistsError(f"{out} already holds checkpoints: pass resume=true to continue that run, "
                                  f"or choose another out_dir")
        return
    found = [name for name in RUN_FILES if (out / name).exists()]
    if found:
        raise FileExistsError(f"{out} holds {', '.join(found)} but no checkpoint (a run killed before its first "
                              f"checkpoint, or another recipe's results): remove {out} or choose another out_dir")

"""``ModelCheckpoint``: resume state of a supervised training run (the VQA and its encoder), written
atomically like ``TrainingCheckpoint``: ``torchrl.checkpoint.Checkpoint`` components (the network,
the optimiser, a ``state`` dict of counters and scores, the global RNG state) staged and renamed into
place by ``CheckpointRotation``, then the SHA-256 of every file (``IntegrityAdapter``), checked before
anything is restored. A checkpoint that cannot be restored raises ``CheckpointCorrupt`` saying what
to do; a missing one is simply not there (``latest()`` is None).
"""

from __future__ import annotations

from pathlib import Path

from torch import nn
from torch.optim import Optimizer
from torchrl.checkpoint import Checkpoint, CheckpointRotation, GlobalRNGState

from mqa_rl.verified_checkpoint import INTEGRITY, CheckpointCorrupt, IntegrityAdapter, newest_checkpoint, restore_verified


class ModelCheckpoint:
    def __init__(self, directory: str | Path, *, model: nn.Module, optimizer: Optimizer, state: dict,
                 keep_last: int = 1):
        self.directory = Path(directory)
        self.rotation = CheckpointRotation(self.directory, keep_last=keep_last)
        self.state = state
        self.checkpoint = Checkpoint(model=model, optimizer=optimizer, trainer_state=state, rng=GlobalRNGState())
        self.checkpoint.register(INTEGRITY, {}, adapter=IntegrityAdapter())

    def save(self, step: int) -> Path:
        return self.rotation.save(self.checkpoint, step=int(step))

    def latest(self) -> Path | None:
        return newest_checkpoint(self.rotation)

    def load(self, path: str | Path | None = None) -> Path:
        """Restore every component in place from ``path`` (default: the newest checkpoint)."""
        path = Path(path) if path is not None else self.latest()
        if path is None:
            raise FileNotFoundError(f"no checkpoint in {self.directory}")
        hint = (f"delete {path} to resume from an older checkpoint in {self.directory}, or start afresh "
                f"with resume=false and another out_dir")
        restore_verified(self.checkpoint, path, hint)
        if "step" not in self.state:
            raise CheckpointCorrupt(f"checkpoint {path} lacks the step counter; {hint}")
        return path

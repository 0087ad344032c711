"""``TrainingCheckpoint``: everything a DQN run needs to continue after SIGKILL, saved atomically.

Components (``torchrl.checkpoint.Checkpoint``, one directory each, written to a hidden stage and
renamed into place; ``CheckpointRotation`` keeps the newest ``keep_last``): the Q-network, the loss
module (online and target parameters), the optimiser, the replay buffer (storage, priorities,
writer cursor), the ε-greedy module (its ε), the run counters (``state``: frames, updates,
episodes, next evaluation / checkpoint frame, target-updater counter, β step counter) and the
global RNG state (python, numpy, torch), and last the SHA-256 of every file of the others
(``mqa_rl.verified_checkpoint.IntegrityAdapter``), checked before anything is restored: a truncated or altered file is refused
instead of being loaded as garbage (a truncated memmap would otherwise read as zeros).

The run is saved between a finished update phase and the next collection, so a resumed run restarts
collection from the saved frame count: no frame is lost or collected twice (the episodes in flight at
the kill are restarted from a reset). A checkpoint that cannot be read raises ``CheckpointCorrupt``
with its path and what to do.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torchrl.checkpoint import Checkpoint, CheckpointError, CheckpointRotation, GlobalRNGState

from mqa_rl.verified_checkpoint import (INTEGRITY, CheckpointCorrupt, IntegrityAdapter, TensorsOnlyReplayAdapter,
                                        newest_checkpoint, restore_verified)

REPLAY = "replay_buffer"          # left out of a checkpoint saved before the first frame (still empty)
SNAPSHOTS = "snapshots"           # <run>/snapshots/checkpoint-<frames>: the policy at fixed frame counts


class TrainingCheckpoint:
    def __init__(self, directory: str | Path, *, actor, loss, optimizer, replay_buffer, egreedy, target_updater,
                 beta_counter: torch.Tensor, state: dict, keep_last: int = 2):
        self.directory = Path(directory)
        self.rotation = CheckpointRotation(self.directory, keep_last=keep_last)
        # the learning curve's points: the Q-network and the counters alone (~1 MB each), every one kept
        self.snapshots = CheckpointRotation(self.directory.parent / SNAPSHOTS, keep_last=1_000_000)
        self.state = state
        self.target_updater = target_updater
        self.beta_counter = beta_counter
        self.checkpoint = Checkpoint(policy=actor, loss=loss, optimizer=optimizer, **{REPLAY: replay_buffer},
                                     exploration=egreedy, trainer_state=state, rng=GlobalRNGState())
        self.checkpoint.register(INTEGRITY, {}, adapter=IntegrityAdapter())
        self.checkpoint.register_adapter(type(replay_buffer), TensorsOnlyReplayAdapter())    # no prefetch.pkl
        self.replay_buffer = replay_buffer

    def save(self) -> Path:
        """Write a checkpoint at the current frame count (atomically); returns its path."""
        self.state["target_updater_counter"] = int(getattr(self.target_updater, "counter", 0))
        self.state["beta_steps"] = int(self.beta_counter)
        components = None
        if not len(self.replay_buffer):     # before the first frame (demonstration pre-training): nothing to save
            components = [name for name in self.checkpoint.components if name != REPLAY]
        return self.rotation.save(self.checkpoint, step=int(self.state["frames"]), components=components)

    def snapshot(self) -> Path:
        """Keep the Q-network at the current frame count in ``<run>/snapshots`` (a checkpoint folder that
        ``evaluate_policy.py checkpoint=`` reads): a learning curve evaluated after the run, never pruned."""
        return self.snapshots.save(self.checkpoint, step=int(self.state["frames"]),
                                   components=["policy", "trainer_state", INTEGRITY])

    def latest(self) -> Path | None:
        return newest_checkpoint(self.rotation)

    def load(self, path: str | Path | None = None) -> Path:
        """Restore every component from ``path`` (default: the newest checkpoint) in place, into a
        fresh run (nothing sampled from the replay yet)."""
        path = Path(path) if path is not None else self.latest()
        if path is None:
            raise FileNotFoundError(f"no checkpoint in {self.directory}")
        if len(self.replay_buffer):
            raise RuntimeError("load a checkpoint into a fresh run only (this replay buffer already holds data)")
        hint = (f"delete {path} to resume from an older checkpoint in {self.directory}, "
                f"or start afresh with resume=false (or another out_dir)")
        try:
            saved = set(Checkpoint.manifest(path)["components"])
        except (CheckpointError, OSError, KeyError, TypeError) as error:
            raise CheckpointCorrupt(f"checkpoint {path} has no readable manifest ({error}); {hint}") from error
        restore_verified(self.checkpoint, path, hint, components=sorted(saved & set(self.checkpoint.components)))
        missing = {"frames", "updates"} - set(self.state)
        if REPLAY not in saved and self.state["frames"]:
            raise CheckpointCorrupt(f"checkpoint {path} has no replay buffer after {self.state['frames']} frames; {hint}")
        if missing:
            raise CheckpointCorrupt(f"checkpoint {path} lacks the run counters {sorted(missing)}; {hint}")
        if hasattr(self.target_updater, "counter"):
            self.target_updater.counter = int(self.state.get("target_updater_counter", 0))
        self.beta_counter.fill_(int(self.state.get("beta_steps", 0)))
        return path

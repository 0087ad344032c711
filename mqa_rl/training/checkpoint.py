"""``TrainingCheckpoint``: everything a DQN run needs to continue after SIGKILL, saved atomically.

Components (``torchrl.checkpoint.Checkpoint``, one directory each, written to a hidden stage and
renamed into place; ``CheckpointRotation`` keeps the newest ``keep_last``): the Q-network, the loss
module (online and target parameters), the optimiser, the replay buffer (storage, priorities,
writer cursor), the ε-greedy module (its ε), the run counters (``state``: frames, updates,
episodes, next evaluation / checkpoint frame, target-updater counter, β step counter) and the
global RNG state (python, numpy, torch), and last the SHA-256 of every file of the others
(``IntegrityAdapter``), checked before anything is restored: a truncated or altered file is refused
instead of being loaded as garbage (a truncated memmap would otherwise read as zeros).

The run is saved between a finished update phase and the next collection, so a resumed run restarts
collection from the saved frame count: no frame is lost or collected twice (the episodes in flight at
the kill are restarted from a reset). A checkpoint that cannot be read raises ``CheckpointCorrupt``
with its path and what to do.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import torch
from torchrl.checkpoint import Checkpoint, CheckpointAdapter, CheckpointError, CheckpointRotation, GlobalRNGState

INTEGRITY = "zz_integrity"        # sorts last: saved after every other component of the checkpoint
REPLAY = "replay_buffer"          # left out of a checkpoint saved before the first frame (still empty)


class CheckpointCorrupt(RuntimeError):
    """A checkpoint exists but cannot be restored (truncated, edited, or from another config)."""


def _digests(components_dir: Path, skip: Path, component: str | None = None) -> dict[str, str]:
    out = {}
    roots = [components_dir] if component is None else sorted(components_dir.glob(f"*-{component}"))
    for f in sorted(f for root in roots for f in root.rglob("*")):
        if f.is_file() and skip not in f.parents:
            h = hashlib.sha256()
            with f.open("rb") as fh:
                for block in iter(lambda: fh.read(1 << 22), b""):
                    h.update(block)
            out[f.relative_to(components_dir).as_posix()] = h.hexdigest()
    return out


class IntegrityAdapter(CheckpointAdapter):
    """Writes the SHA-256 of the files of the components saved before it (they sort first)."""

    adapter_id = "mqa_rl.sha256"
    format_version = 1

    def save(self, component, path: Path, *, args, kwargs):
        path.mkdir(parents=True, exist_ok=True)
        (path / "sha256.json").write_text(json.dumps(_digests(path.parent, path), indent=0))

    def load(self, component, path: Path, *, map_location, tensor_load_kwargs, args, kwargs):
        return None                       # verified before loading (TrainingCheckpoint.verify)

    @staticmethod
    def verify(checkpoint_dir: Path, component: str | None = None) -> None:
        """Raise ``ValueError`` naming the files that are missing or differ from their digests; with
        ``component`` (e.g. ``"policy"``) only that component's files (not the whole replay buffer)."""
        found = list((checkpoint_dir / "components").glob(f"*{INTEGRITY}/sha256.json"))
        if not found:
            raise ValueError("no integrity record (sha256.json): not a complete mqa_rl training checkpoint")
        expected = json.loads(found[0].read_text())
        actual = _digests(checkpoint_dir / "components", found[0].parent, component)
        if component is not None:
            expected = {k: v for k, v in expected.items() if k.split("/", 1)[0].endswith(f"-{component}")}
            if not expected:
                raise ValueError(f"the integrity record lists no file of the {component!r} component")
        bad = sorted(k for k in expected if actual.get(k) != expected[k]) + sorted(set(actual) - set(expected))
        if bad:
            raise ValueError(f"{len(bad)} file(s) missing or changed since saved, e.g. {bad[:3]}")


class TrainingCheckpoint:
    def __init__(self, directory: str | Path, *, actor, loss, optimizer, replay_buffer, egreedy, target_updater,
                 beta_counter: torch.Tensor, state: dict, keep_last: int = 2):
        self.directory = Path(directory)
        self.rotation = CheckpointRotation(self.directory, keep_last=keep_last)
        self.state = state
        self.target_updater = target_updater
        self.beta_counter = beta_counter
        self.checkpoint = Checkpoint(policy=actor, loss=loss, optimizer=optimizer, **{REPLAY: replay_buffer},
                                     exploration=egreedy, trainer_state=state, rng=GlobalRNGState())
        self.checkpoint.register(INTEGRITY, {}, adapter=IntegrityAdapter())
        self.replay_buffer = replay_buffer

    def save(self) -> Path:
        """Write a checkpoint at the current frame count (atomically); returns its path."""
        self.state["target_updater_counter"] = int(getattr(self.target_updater, "counter", 0))
        self.state["beta_steps"] = int(self.beta_counter)
        components = None
        if not len(self.replay_buffer):     # before the first frame (demonstration pre-training): nothing to save
            components = [name for name in self.checkpoint.components if name != REPLAY]
        return self.rotation.save(self.checkpoint, step=int(self.state["frames"]), components=components)

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


def newest_checkpoint(rotation: CheckpointRotation) -> Path | None:
    """The newest checkpoint of ``rotation``; ``CheckpointCorrupt`` if a newer one on disk cannot be read (no
    valid manifest), rather than silently resuming from an older one or starting afresh over a run's logs."""
    directory = Path(rotation.directory)
    if not directory.exists():
        return None
    latest = rotation.latest()

    def step(path: Path) -> int:          # checkpoint-<step>[.torchrl]; -1: not a checkpoint name
        text = path.name.removesuffix(".torchrl").removeprefix(f"{rotation.prefix}-")
        return int(text) if text.isdigit() else -1

    floor = step(latest) if latest is not None else -1
    unreadable = sorted((p for p in directory.glob(f"{rotation.prefix}-*") if step(p) > floor), key=step)
    if unreadable:
        names = [p.name for p in unreadable]
        older = f"; the newest readable one is {latest.name}" if latest is not None else ""
        raise CheckpointCorrupt(f"{directory} holds {names}, which cannot be read (no valid manifest){older}: "
                                f"delete {names} to resume from an older checkpoint or start afresh, "
                                f"or choose another out_dir")
    return latest


def restore_verified(checkpoint, path: Path, hint: str, components: list[str] | None = None) -> None:
    """``checkpoint.load(path)`` (its ``components``, default all) after checking every file's SHA-256; any
    failure → ``CheckpointCorrupt`` saying ``hint`` (what to do)."""
    try:
        IntegrityAdapter.verify(path)
        checkpoint.load(path, components=components, strict="error")
    except (CheckpointError, OSError, ValueError, KeyError, RuntimeError, EOFError) as error:
        raise CheckpointCorrupt(f"checkpoint {path} cannot be restored ({type(error).__name__}: "
                                f"{str(error)[:500]}); {hint}") from error

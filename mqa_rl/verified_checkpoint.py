"""TorchRL checkpoints whose files are checked before anything is read: just above ``files.py`` at the bottom
of the house (imports nothing else from mqa_rl), so that the modules that load a shipped policy and the
training loops that save and resume runs share one format without importing each other.

``IntegrityAdapter`` is the last component of a checkpoint: the SHA-256 of every file of the others,
checked before anything is restored, so a truncated or altered file is refused instead of being
loaded as garbage (a truncated memmap would otherwise read as zeros). ``newest_checkpoint`` finds the
newest readable checkpoint of a rotation and names newer unreadable ones instead of skipping them;
``restore_verified`` loads after the check. A checkpoint holds tensors and JSON only: a pickled file in it
(a crafted ``other.pickle`` leaf or ``prefetch.pkl``) is refused before anything is read, since the
SHA-256 record sits beside the files and anyone can reseal it; ``TensorsOnlyReplayAdapter`` saves a
replay buffer without TorchRL's ``prefetch.pkl``. A checkpoint that cannot be read raises
``CheckpointCorrupt`` with its path and what to do. The resumable runs built on it are
``mqa_rl.training.checkpoint`` (DQN) and ``mqa_rl.training.model_checkpoint`` (VQA, encoder).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from torchrl.checkpoint import CheckpointAdapter, CheckpointError, CheckpointRotation, DumpLoadCheckpointAdapter

from mqa_rl.files import refuse_pickles

INTEGRITY = "zz_integrity"        # sorts last: saved after every other component of the checkpoint


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


def _integrity_record(checkpoint_dir: Path, component: str | None = None) -> tuple[Path, dict[str, str]]:
    """(the record's file, its digests: all, or ``component``'s files only); ValueError when there is none."""
    found = list((Path(checkpoint_dir) / "components").glob(f"*{INTEGRITY}/sha256.json"))
    if not found:
        raise ValueError(f"{checkpoint_dir}: no integrity record (sha256.json): not a complete mqa_rl training checkpoint")
    record = json.loads(found[0].read_text())
    if component is not None:
        record = {k: v for k, v in record.items() if k.split("/", 1)[0].endswith(f"-{component}")}
    return found[0], record


def component_digest(checkpoint_dir: Path, component: str) -> str:
    """One SHA-256 for a component's files as the checkpoint's integrity record lists them (``"policy"``: the
    weights): what tells two evaluations they ran the same policy, without hashing the files again."""
    return hashlib.sha256(json.dumps(dict(sorted(_integrity_record(checkpoint_dir, component)[1].items()))).encode()).hexdigest()


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
        roots = [checkpoint_dir / "components"] if component is None else \
            sorted((checkpoint_dir / "components").glob(f"*-{component}"))
        for root in roots:
            refuse_pickles(root, what="the checkpoint", hint="mqa_rl's checkpoints hold tensors and JSON only; use a "
                                                           "checkpoint from a source you trust")
        record, expected = _integrity_record(checkpoint_dir, component)
        actual = _digests(checkpoint_dir / "components", record.parent, component)
        if component is not None:
            if not expected:
                raise ValueError(f"the integrity record lists no file of the {component!r} component")
        bad = sorted(k for k in expected if actual.get(k) != expected[k]) + sorted(set(actual) - set(expected))
        if bad:
            raise ValueError(f"{len(bad)} file(s) missing or changed since saved, e.g. {bad[:3]}")


class TensorsOnlyReplayAdapter(DumpLoadCheckpointAdapter):
    """A replay buffer's ``dumps`` (storage, sampler and writer state: memmaps and JSON) without the
    ``prefetch.pkl`` TorchRL adds, a pickle of the batches prefetched but not yet sampled, which an mqa_rl buffer
    never has (it samples without prefetch). Loading reads the same format (no prefetch file: none pending)."""

    def save(self, component, path: Path, *, args, kwargs):
        out = super().save(component, path, args=args, kwargs=kwargs)
        prefetch = Path(path) / "prefetch.pkl"
        if prefetch.exists():
            if getattr(component, "_prefetch_queue", None):
                raise RuntimeError("the replay buffer holds prefetched batches, which a checkpoint could only keep "
                                   "as a pickle: build it without prefetch")
            prefetch.unlink()
        return out


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

"""``EpisodeStore``: records (one per episode or frame) on disk as memmap TensorDict chunks,
written atomically and resumable.

Layout of a store folder::

    meta.json          what is collected (dataset fingerprint, policy, plan, env); fixed at creation
    chunk-00000/       a memmap TensorDict [N] (``TensorDict.memmap``), records keyed by ``slot``
    chunk-00001/ ...
    .lock              held (flock) by the one process writing

Every chunk is written to a hidden ``.chunk-*.tmp-<pid>`` folder and renamed into place when
complete, so a killed collection leaves only whole chunks (and a hidden folder, removed on the next
open). Each record carries its ``slot`` (its position in the collection plan): an interrupted
collection resumes by running the slots no chunk holds, so nothing is collected twice; at most one
chunk of work in flight is redone. Opening a folder whose ``meta.json`` differs from the plan asked
for (another policy, dataset or plan) is refused rather than mixing two collections.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
from pathlib import Path

import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.files import load_memmap, write_atomic

META = "meta.json"
SCENE_OFFSET = 1_000_000      # records of several stores (datasets) read together: scene ids + k · SCENE_OFFSET
CHUNK_PREFIX = "chunk-"


class StoreError(ValueError):
    """A store folder that belongs to another collection, or is incomplete or inconsistent."""


def _comparable(meta: dict) -> dict:
    """``meta`` without what may change between runs of the same collection (where the dataset lies)."""
    out = json.loads(json.dumps(meta))
    out.get("dataset", {}).pop("root", None)
    return out


class EpisodeStore:
    """A store folder (see the module docstring). ``meta`` must be JSON-serialisable and include
    ``"slots"``, the number of records the plan holds."""

    def __init__(self, root: str | Path, meta: dict, *, overwrite: bool = False):
        self.root = Path(root)
        self.meta = json.loads(json.dumps(meta))
        if "slots" not in self.meta:
            raise ValueError("store meta needs 'slots' (the number of records planned)")
        if self.root.exists() and not self.root.is_dir():
            raise StoreError(f"{self.root} is a file, not a store folder: choose another out_dir")
        self.root.mkdir(parents=True, exist_ok=True)
        self._lock = open(self.root / ".lock", "a")         # never truncated or replaced: one inode for every writer
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._lock.close()
            raise StoreError(f"{self.root} is being written by another process; wait for it or choose another out_dir") from None
        if overwrite:                   # only once the lock is ours: another writer's chunks are never removed
            for entry in self.root.iterdir():
                if entry.name != ".lock":
                    shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
        for leftover in self.root.glob(f".{CHUNK_PREFIX}*"):       # a killed writer's partial chunk
            shutil.rmtree(leftover, ignore_errors=True)
        path = self.root / META
        if path.exists() and not chunk_paths(self.root):
            path.unlink()               # a collection that stored nothing (its policy failed to load): nothing to keep
        if path.exists():
            found = read_meta(self.root)
            if _comparable(found) != _comparable(self.meta):
                diff = sorted(k for k in set(found) | set(self.meta) if _comparable(found).get(k) != _comparable(self.meta).get(k))
                raise StoreError(f"{self.root} holds another collection (differs in {diff}); choose another out_dir, "
                                 f"or pass overwrite=true to replace it")
        else:
            write_atomic(path, json.dumps(self.meta, indent=1, sort_keys=True))

    def close(self) -> None:
        if not self._lock.closed:
            fcntl.flock(self._lock, fcntl.LOCK_UN)
            self._lock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------------------------ write
    def chunk_paths(self) -> list[Path]:
        return chunk_paths(self.root)

    def done_slots(self) -> set[int]:
        done: set[int] = set()
        for path in self.chunk_paths():
            slots = read_chunk(path).get(keys.SLOT).tolist()
            if done.intersection(slots):
                raise StoreError(f"{path} repeats slots already stored in {self.root}: remove that chunk")
            done.update(slots)
        return done

    def append(self, records: TensorDict) -> Path:
        """Write ``records`` [N] (with ``slot``) as the next chunk, atomically."""
        if records.batch_dims != 1 or keys.SLOT not in records.keys():
            raise ValueError("records must be a TensorDict [N] holding 'slot'")
        paths = self.chunk_paths()
        index = int(paths[-1].name[len(CHUNK_PREFIX):]) + 1 if paths else 0
        final = self.root / f"{CHUNK_PREFIX}{index:05d}"
        tmp = self.root / f".{final.name}.tmp-{os.getpid()}"
        records.memmap(prefix=str(tmp))
        os.replace(tmp, final)
        return final


def read_chunk(path: Path) -> TensorDict:
    """One stored chunk (a memmap TensorDict of tensors and JSON): a pickled leaf is refused, never unpickled."""
    return load_memmap(path, what="the rollout chunk", hint="delete that chunk: the next run of the same command "
                                                           "collects its episodes again")


def chunk_paths(root: str | Path) -> list[Path]:
    return sorted(p for p in Path(root).glob(f"{CHUNK_PREFIX}[0-9]*") if p.is_dir())


def read_meta(root: str | Path) -> dict:
    path = Path(root) / META
    if not path.exists():
        raise FileNotFoundError(f"no collection at {root} (no {META}): collect it first (recipes/collect.py what=rollouts "
                                f"for a system's rollouts, recipes/collect.py what=frames for the perception's frames)")
    try:
        return json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise StoreError(f"{path} is not readable JSON ({error}): the store is damaged; collect it again "
                         f"(the collecting recipe with overwrite=true)") from None


def load_records(root: str | Path, select=None, *, require_complete: bool = True, rows: torch.Tensor | None = None) -> TensorDict:
    """All records of a store as one in-memory TensorDict [N], sorted by slot.

    ``select``: the keys to read (e.g. leave the depth images on disk). ``require_complete``: raise
    ``StoreError`` when fewer records than planned are stored (an interrupted collection). ``rows``: bool
    [N] over the records in slot order, read only those (a training split without a second copy).
    Each chunk is read straight into one preallocated TensorDict: memory peaks at what is returned plus
    one chunk, not at three copies of the store."""
    root = Path(root)
    meta = read_meta(root)
    chunks = [read_chunk(path) for path in chunk_paths(root)]
    if select is not None:
        chunks = [td.select(*select, keys.SLOT) for td in chunks]
    if not chunks:
        if require_complete:
            raise StoreError(f"{root} holds no records yet: run (or resume) its collection")
        return TensorDict({}, batch_size=[0])
    slots = torch.cat([td.get(keys.SLOT).clone() for td in chunks])
    order = torch.argsort(slots)
    if (slots[order][1:] == slots[order][:-1]).any():
        raise StoreError(f"{root} holds a slot twice: a chunk was copied in by hand?")
    if require_complete and slots.shape[0] < int(meta["slots"]):
        raise StoreError(f"{root} holds {slots.shape[0]} of {meta['slots']} planned records: the collection was "
                         f"interrupted; run the same command again to finish it")
    if rows is None:
        rows = torch.ones(slots.shape[0], dtype=torch.bool)
    elif rows.dtype != torch.bool or rows.shape != slots.shape:
        raise ValueError(f"rows must be a bool mask over the {slots.shape[0]} records of {root}, got {rows.dtype} {tuple(rows.shape)}")
    rank = torch.empty_like(order)
    rank[order] = torch.arange(order.shape[0])          # each stored record's place in slot order
    keep = rows[rank]
    dest = (torch.cumsum(rows.long(), 0) - 1)[rank]     # its place among the rows kept
    n = int(rows.sum())
    out = empty_records(chunks[0], n)
    start = 0
    for j, td in enumerate(chunks):
        stop = start + td.shape[0]
        k = keep[start:stop]
        if k.any():
            out[dest[start:stop][k]] = td[k]            # memmap → memory, this chunk's kept rows only
        start, chunks[j] = stop, None                   # and its mapping let go
    return out


def empty_records(like: TensorDict, n: int) -> TensorDict:
    """An uninitialised in-memory TensorDict [n] with ``like``'s keys, dtypes and per-record shapes: filled in place,
    so a store is read without a second copy of it."""
    return like[:1].apply(lambda x: torch.empty((n, *x.shape[1:]), dtype=x.dtype), batch_size=[n])

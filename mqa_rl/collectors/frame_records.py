"""Reading the perception's labelled frames (``perception_frames`` writes them; its docstring says what a record holds).

Kept apart from the collector so that training imports no simulator: the frames are rendered where
SAPIEN runs and may be trained on where a GPU is and SAPIEN is not (``tools/carry_store.py``).
"""

from __future__ import annotations

from pathlib import Path

import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.store import SCENE_OFFSET, empty_records, load_records, read_meta

SCHEMA = 2        # 2: frames hold depth
DEPTH_SCHEMA = 2  # the first schema whose frames hold depth


def pile_offsets(stores) -> list[int]:
    """The scene-id offset of each store: one per dataset (its manifest's SHA-256), so that two stores of the same
    piles (a second collection with another seed) give a pile the same id and a split by scene holds it out of both;
    a store that names no dataset gets its own."""
    datasets: dict[str, int] = {}
    offsets = []
    for i, store in enumerate(stores):
        sha = (read_meta(store).get("dataset") or {}).get("manifest_sha256") or f"store {i}"
        offsets.append(datasets.setdefault(sha, len(datasets)) * SCENE_OFFSET)
    return offsets


def load_frames(stores, select=None, rows: torch.Tensor | None = None) -> TensorDict:
    """The frames of one or more stores as one TensorDict [N] in memory; scene ids name piles: distinct per dataset,
    the same for two stores of one dataset (``pile_offsets``).

    ``rows``: bool [N] over all the stores' frames (in the order this returns them), read only those:
    pick the rows from a first read of a few small keys (scene, level), then read the images of each side
    of a split. Each store is copied into one preallocated TensorDict, so memory peaks at the frames
    returned plus one store's share, never at two copies of everything."""
    stores = [stores] if isinstance(stores, (str, Path)) else list(stores)
    counts = [len(load_records(store, [keys.SLOT], require_complete=False)) for store in stores]
    if rows is not None and rows.shape[0] != sum(counts):
        raise ValueError(f"rows has {rows.shape[0]} entries, the stores hold {sum(counts)} frames")
    masks = rows.split(counts) if rows is not None else [None] * len(stores)
    total = sum(counts) if rows is None else int(rows.sum())
    out, at = None, 0
    offsets = pile_offsets(stores)
    for i, (store, mask) in enumerate(zip(stores, masks)):
        if counts[i] == 0:
            raise ValueError(f"{store} holds no frames yet: run recipes/collect.py what=frames")
        td = load_records(store, select, require_complete=False, rows=mask)
        td.set(keys.SCENE, td.get(keys.SCENE) + offsets[i])
        if len(stores) == 1:
            return td
        if out is None:
            out = empty_records(td, total)
        out[at:at + td.shape[0]] = td
        at += td.shape[0]
        del td
    return out

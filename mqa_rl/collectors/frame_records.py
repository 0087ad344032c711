"""Reading the perception's labelled frames (``perception_frames`` writes them; its docstring says what a record holds).

Kept apart from the collector so that training imports no simulator: the frames are rendered where
SAPIEN runs and may be trained on where a GPU is and SAPIEN is not (``tools/carry_store.py``).
"""

from __future__ import annotations

from pathlib import Path

import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.store import SCENE_OFFSET, load_records

SCHEMA = 2        # 2: frames hold depth
DEPTH_SCHEMA = 2  # the first schema whose frames hold depth


def load_frames(stores, select=None) -> TensorDict:
    """The frames of one or more stores as one TensorDict [N] in memory; scene ids made distinct per store."""
    parts = []
    for i, store in enumerate([stores] if isinstance(stores, (str, Path)) else list(stores)):
        td = load_records(store, select, require_complete=False)
        if td.shape[0] == 0:
            raise ValueError(f"{store} holds no frames yet: run recipes/collect_frames.py")
        td.set(keys.SCENE, td.get(keys.SCENE) + i * SCENE_OFFSET)
        parts.append(td)
    return torch.cat(parts)

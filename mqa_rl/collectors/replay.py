"""Prioritized replay (the paper's anchor VPG) over a memory-mapped storage, sized for 24 GiB machines.

A transition keeps only what ``DQNLoss`` reads: rgb (uint8), depth (float16: 0.5 mm steps at 0.9 m),
question, action mask, action, the visible-target cells (float16, for the auxiliary loss of
``target_map.py``), and under ``"next"`` the same observations plus reward and done flags.
``info`` and the reward terms stay out (the logs read them from the collected batch). See
``transition_bytes`` for the size; the storage is a memmap on disk, so RAM holds only the pages in use.

Priorities are the loss's ``td_error`` (the squared TD error δ²): α applies to δ², so α = 0.3 weighs
transitions like the usual |δ|^0.6. The importance-sampling exponent β anneals linearly to 1.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import torch
from tensordict import TensorDictBase
from torchrl.data import LazyMemmapStorage, LazyTensorStorage, TensorDictPrioritizedReplayBuffer

from mqa_rl import keys
from mqa_rl.envs.dihedral import DihedralAugment

OBS_KEYS = (keys.RGB, keys.DEPTH, keys.QUESTION, keys.ACTION_MASK)
REPLAY_KEYS = (
    *OBS_KEYS, keys.ACTION, keys.TARGET_CELLS,
    *(("next", k) for k in (*OBS_KEYS, keys.REWARD, "done", "terminated", "truncated")),
)


def compact_transitions(data: TensorDictBase) -> TensorDictBase:
    """Collected transitions [N] → what the replay stores: selected keys, depth as float16."""
    out = data.select(*REPLAY_KEYS, strict=True)
    for key in (keys.DEPTH, ("next", keys.DEPTH), keys.TARGET_CELLS):
        out.set(key, out.get(key).to(torch.float16))
    return out


def transition_bytes(example: TensorDictBase) -> int:
    """Bytes one stored transition takes (sum over its tensors)."""
    return sum(t.numel() * t.element_size() for t in example.values(True, True))


def make_replay_buffer(cfg: Mapping, scratch_dir: str | Path | None) -> TensorDictPrioritizedReplayBuffer:
    """From the ``buffer`` config: size, batch_size, alpha, beta_init, storage (memmap | memory),
    augment (none | dihedral: each sample under a random symmetry of the square bin, ``mqa_rl.envs.dihedral``)."""
    size, batch = int(cfg["size"]), int(cfg["batch_size"])
    if size < batch or batch < 1:
        raise ValueError(f"buffer.size={size} must be ≥ buffer.batch_size={batch} ≥ 1")
    if cfg.get("storage", "memmap") == "memmap":
        if scratch_dir is None:
            raise ValueError("a memmap replay buffer needs a scratch directory")
        storage = LazyMemmapStorage(size, scratch_dir=str(scratch_dir))
    elif cfg["storage"] == "memory":
        storage = LazyTensorStorage(size)
    else:
        raise ValueError(f"buffer.storage={cfg['storage']!r}; choose 'memmap' (disk) or 'memory'")
    augment = cfg.get("augment", "none")
    if augment not in ("none", "dihedral"):
        raise ValueError(f"buffer.augment={augment!r}; choose 'none' or 'dihedral'")
    rb = TensorDictPrioritizedReplayBuffer(alpha=float(cfg.get("alpha", 0.6)), beta=float(cfg.get("beta_init", 0.4)),
                                           priority_key=keys.TD_ERROR, storage=storage, batch_size=batch)
    if augment == "dihedral":
        rb.append_transform(DihedralAugment())
    return rb


def annealed_is_beta(beta_init: float, progress: float) -> float:
    """Importance-sampling β: linear from ``beta_init`` to 1 as training ``progress`` goes 0 → 1."""
    p = min(max(progress, 0.0), 1.0)
    return beta_init + (1.0 - beta_init) * p if math.isfinite(p) else 1.0

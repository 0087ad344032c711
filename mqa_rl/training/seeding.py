"""A run's seeds and threads, set once the same way by every training recipe (torch, numpy, random; ``threads``:
torch's intra-op threads, None leaves torch's default)."""

from __future__ import annotations

import random

import numpy as np
import torch


def seed_run(seed: int, threads: int | None = None) -> None:
    torch.manual_seed(seed)
    np.random.seed(seed)
    random.seed(seed)
    if threads:
        torch.set_num_threads(threads)

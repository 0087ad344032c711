"""What the env measures per object, as pure torch functions: the overlap rate χ from the visible and
the full projected area. The reward terms (``mqa_rl.transforms``) read these measurements; they do
not compute them.
"""

from __future__ import annotations

import torch


def overlap_rate(visible_area: torch.Tensor, full_area: torch.Tensor) -> torch.Tensor:
    """χ = 1 − A_s / A_t, clipped to [0, 1]; an object out of view (A_t = 0) counts as χ = 1."""
    full = full_area.to(torch.float32)
    chi = 1.0 - visible_area.to(torch.float32) / full.clamp(min=1e-9)
    return torch.where(full > 0, chi.clamp(0.0, 1.0), torch.ones_like(chi))

"""The paper's action space: 8 push directions on a 28 × 28 grid of image cells, plus stop.

Index ``a = d * 784 + row * 28 + col`` pushes from the centre of grid cell (row, col) of the image in
direction ``d * 45°``; ``a = 6272`` is stop. **0° points to the image's right (world +x) and angles
turn counter-clockwise as seen in the image** (90° = image up = world +y), so direction d moves
objects along world (cos d·45°, sin d·45°).
"""

from __future__ import annotations

import math

import numpy as np
import torch

GRID = 28
DIRECTIONS = 8
NUM_PUSHES = DIRECTIONS * GRID * GRID       # 6272
STOP = NUM_PUSHES
NUM_ACTIONS = NUM_PUSHES + 1                 # 6273


def encode(direction: int, row: int, col: int) -> int:
    if not (0 <= direction < DIRECTIONS and 0 <= row < GRID and 0 <= col < GRID):
        raise ValueError(f"push (d={direction}, row={row}, col={col}) outside d∈[0,{DIRECTIONS}), row/col∈[0,{GRID})")
    return direction * GRID * GRID + row * GRID + col


def decode(action: int) -> tuple[int, int, int]:
    """Push index → (direction, row, col). Raises for stop or out of range."""
    if not 0 <= action < NUM_PUSHES:
        raise ValueError(f"push index {action} outside [0, {NUM_PUSHES}) (stop is {STOP})")
    d, rest = divmod(int(action), GRID * GRID)
    row, col = divmod(rest, GRID)
    return d, row, col


def direction_xy(direction: int) -> np.ndarray:
    """Unit world-xy vector of push direction d."""
    theta = math.radians(45.0 * direction)
    return np.array([math.cos(theta), math.sin(theta)])


def cell_centre_uv(row: int, col: int, height: int, width: int) -> np.ndarray:
    """Continuous image coordinates (u, v) of grid cell (row, col)'s centre."""
    return np.array([(col + 0.5) * width / GRID, (row + 0.5) * height / GRID])


def push_start_points(depth: np.ndarray, camera) -> np.ndarray:
    """World start point [GRID, GRID, 3] of the push from every cell, as ``SapienBinEnv`` computes it:
    the surface under the cell centre's pixel (from the depth image, metres along the view axis),
    the floor where the depth is empty."""
    h, w = depth.shape[-2:]
    rows, cols = np.meshgrid(np.arange(GRID), np.arange(GRID), indexing="ij")
    uv = np.stack([(cols + 0.5) * w / GRID, (rows + 0.5) * h / GRID], axis=-1)
    z = depth[np.minimum(uv[..., 1].astype(int), h - 1), np.minimum(uv[..., 0].astype(int), w - 1)].astype(np.float64)
    z = np.where(z > 0, z, camera.distance)
    return camera.unproject(uv, z)


def push_start_mask(bin_spec, camera, depth: np.ndarray, margin: float = 0.005) -> torch.Tensor:
    """bool [NUM_ACTIONS]: True for pushes that start inside the bin, and for stop.

    A push starts at the surface point under its cell (``push_start_points``); it is allowed when
    that point lies inside the inner walls shrunk by ``margin`` (so not on a wall face, the rim or
    outside the bin). Pile tops next to a wall are allowed, the wall beside them is not. Derived from
    the bin, the camera and the current depth image only, so it follows whatever geometry the
    dataset has. The same cells are allowed in every direction; stop is always allowed.
    """
    return start_points_mask(bin_spec, push_start_points(depth, camera), margin)


def start_points_mask(bin_spec, start: np.ndarray, margin: float = 0.005) -> torch.Tensor:
    """``push_start_mask`` from already computed start points [GRID, GRID, 3]."""
    inside = torch.from_numpy(bin_spec.inside(start, margin=margin).reshape(-1))
    return torch.cat([inside.repeat(DIRECTIONS), torch.ones(1, dtype=torch.bool)])


def random_push(action_mask: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """A push drawn uniformly among those an observation's ``action_mask`` [NUM_ACTIONS] allows (stop excluded): the
    random pushes that disturb piles for the frame collectors and the benchmarks."""
    return torch.multinomial(action_mask[:NUM_PUSHES].float(), 1, generator=generator).squeeze(0)

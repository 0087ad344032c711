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


def push_start_mask(bin_spec, camera) -> torch.Tensor:
    """bool [NUM_ACTIONS]: True for pushes whose cell centre lies over the bin floor, and for stop.

    Derived from the geometry (the cell centre's ray meets the floor z = 0 inside the inner walls), so
    it follows whatever bin size and camera framing the dataset has. The same cells are allowed in
    every direction; stop is always allowed.
    """
    rows, cols = np.meshgrid(np.arange(GRID), np.arange(GRID), indexing="ij")
    uv = np.stack([(cols + 0.5) * camera.width / GRID, (rows + 0.5) * camera.height / GRID], axis=-1)
    floor = camera.unproject(uv, np.full(uv.shape[:-1], camera.distance))
    inside = torch.from_numpy(bin_spec.inside(floor).reshape(-1))
    return torch.cat([inside.repeat(DIRECTIONS), torch.ones(1, dtype=torch.bool)])

"""Bin scenes: objects thrown into the bin in SAPIEN and settled, as the paper's V-REP scenes were.

Objects fall in waves of ``WAVE`` from just above the current pile, with random orientations, inside
temporarily raised walls (so nothing bounces out while falling). A scene is accepted when every
object sleeps (PhysX's rest test) within ``MAX_SETTLE_STEPS`` and rests inside the real bin: centre
within the inner walls and below the wall top. Otherwise it is dropped again with fresh randomness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mqa_rl.sim.assets import ObjectAsset
from mqa_rl.sim.geometry import BinSpec

DIFFICULTIES = {"easy": 20, "medium": 35, "hard": 50}   # objects per scene (paper, Sec. III-C)
WAVE = 9                        # objects released together (a 3 × 3 grid)
WAVE_STEPS = 90                 # physics steps between waves (0.375 s)
MAX_SETTLE_STEPS = 2400         # 10 s of simulated time
MAX_ATTEMPTS = 10
DROP_WALL_HEIGHT = 0.6          # walls while dropping (m)
VERIFY_STEPS = 240              # 1 s of simulated time
VERIFY_ROUNDS = 4
REST_TOLERANCE = 0.002          # m


class SceneGenerationError(RuntimeError):
    pass


@dataclass(frozen=True)
class SettledScene:
    object_indices: np.ndarray      # [n] indices into the object library, in drop order
    poses: np.ndarray               # [n, 7] settled poses (x, y, z, qw, qx, qy, qz), float32-exact
    attempts: int
    settle_steps: int


def _f32(x: np.ndarray) -> np.ndarray:
    """Poses as stored (float32 precision), in float64 arrays."""
    return np.asarray(x, np.float32).astype(np.float64)


def _drop_poses(rng: np.random.Generator, assets: list[ObjectAsset], base_z: float, bin_spec: BinSpec) -> np.ndarray:
    """Poses for one wave: a jittered 3 × 3 grid, random orientations, bottoms above ``base_z``."""
    n = len(assets)
    cell = (bin_spec.inner_size - 0.08) / 3
    slots = rng.permutation(9)[:n]
    xy = (np.stack([slots % 3, slots // 3], 1) - 1.0) * cell + rng.uniform(-0.01, 0.01, (n, 2))
    quat_xyzw = Rotation.random(n, random_state=rng).as_quat()
    radius = np.array([np.linalg.norm(a.dimensions) / 2 for a in assets])
    z = base_z + radius.max() + 0.01
    poses = np.zeros((n, 7))
    poses[:, :2] = xy
    poses[:, 2] = z
    poses[:, 3] = quat_xyzw[:, 3]
    poses[:, 4:] = quat_xyzw[:, :3]
    return poses


def settle_scene(
    assets: list[ObjectAsset], indices: np.ndarray, rng: np.random.Generator, bin_spec: BinSpec = BinSpec()
) -> SettledScene:
    """Throw ``assets[indices]`` into the bin and let them settle; re-drop until valid."""
    from mqa_rl.sim.scene import add_object, build_world

    chosen = [assets[i] for i in indices]
    drop_bin = BinSpec(bin_spec.inner_size, DROP_WALL_HEIGHT, bin_spec.wall_thickness)
    for attempt in range(1, MAX_ATTEMPTS + 1):
        world = build_world([], np.zeros((0, 7)), bin_spec=drop_bin)
        steps = 0
        for start in range(0, len(chosen), WAVE):
            wave = chosen[start:start + WAVE]
            top = max((p[2] for p in world.poses()), default=0.0)
            for asset, pose in zip(wave, _drop_poses(rng, wave, top + 0.02, bin_spec)):
                add_object(world, asset, pose)
            world.step(WAVE_STEPS)
            steps += WAVE_STEPS
        steps += world.settle(MAX_SETTLE_STEPS)
        poses = _f32(world.poses())
        for _ in range(VERIFY_ROUNDS):
            if not (world.all_asleep() and np.all(np.isfinite(poses))):
                break
            if not (bin_spec.inside(poses[:, :3]) & (poses[:, 2] < bin_spec.wall_height)).all():
                break
            world = build_world(chosen, poses, bin_spec=bin_spec, asleep=False)
            world.step(VERIFY_STEPS)
            steps += VERIFY_STEPS
            moved = np.linalg.norm(world.poses()[:, :3] - poses[:, :3], axis=1).max()
            if moved < REST_TOLERANCE:
                return SettledScene(np.asarray(indices), poses, attempt, steps)
            steps += world.settle(MAX_SETTLE_STEPS)
            poses = _f32(world.poses())
    raise SceneGenerationError(f"no valid settled scene after {MAX_ATTEMPTS} drops of {len(indices)} objects")

"""Bin scenes: objects thrown into the bin in SAPIEN and settled, as the paper's V-REP scenes were.

"The objects are thrown into the bin randomly": like the contents of a box emptied into a tote, the
objects are poured one by one (random orientations, xy jitter ``DROP_SPREAD``, each released just
above the current pile) into a square sleeve of ``SLEEVE_SIZE`` standing at a random point near the
bin centre; the sleeve is then lifted at ``SLEEVE_LIFT_SPEED`` and the column slumps into a pile.
With real-size objects this hides objects under others at every level (the task's premise; without
the sleeve, 20 objects spread into one layer and almost nothing is hidden). A scene is accepted when
every object sleeps within ``MAX_SETTLE_STEPS`` and rests inside the real bin (centre within the
inner walls and below the wall top), and when it is a true rest state: rebuilt awake from the
stored float32 poses, nothing moves more than ``REST_TOLERANCE`` in ``VERIFY_STEPS``. Otherwise it
is dropped again with fresh randomness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mqa_rl.sim.assets import ObjectAsset
from mqa_rl.sim.geometry import BinSpec

DIFFICULTIES = {"easy": 20, "medium": 35, "hard": 50}   # objects per scene (paper, Sec. III-C)
MAX_OBJECTS = max(DIFFICULTIES.values())                 # object slots of every per-object tensor
WAVE = 1                        # objects released together, as one column (1: poured one by one)
WAVE_STEPS = 40                 # physics steps between waves (1/6 s)
DROP_SPREAD = 0.03              # σ of each object's xy offset from the drop point (m)
DROP_POINT_RANGE = 0.05         # the drop point is uniform in ±this around the bin centre (m)
SLEEVE_SIZE = 0.25              # inner side of the tube the objects are poured into (m); 0: none
SLEEVE_LIFT_SPEED = 0.2         # m/s
MAX_SETTLE_STEPS = 2400         # 10 s of simulated time
MAX_ATTEMPTS = 10
DROP_WALL_HEIGHT = 1.5          # walls and sleeve while pouring (m): a poured column reaches ~1.4 m
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


def _bounding_radius(asset: ObjectAsset) -> float:
    return float(np.linalg.norm(asset.dimensions) / 2)


def _pile_top(world) -> float:
    """An upper bound of the pile's height: the highest centre plus that object's bounding radius."""
    return max((p[2] + _bounding_radius(a) for p, a in zip(world.poses(), world.assets)), default=0.0)


def _column_poses(rng: np.random.Generator, assets: list[ObjectAsset], base_z: float, point: np.ndarray,
                  bin_spec: BinSpec) -> np.ndarray:
    """Poses for one wave: a column above ``point``, each object's bounding sphere clear of the one
    below, xy jittered by ``DROP_SPREAD`` (kept inside the walls), random orientations."""
    n = len(assets)
    radius = np.array([_bounding_radius(a) for a in assets])
    lim = bin_spec.half - radius[:, None]
    offset = rng.normal(0.0, DROP_SPREAD, (n, 2))
    if SLEEVE_SIZE:
        offset = np.clip(offset, -(SLEEVE_SIZE / 2 - 0.03), SLEEVE_SIZE / 2 - 0.03)
    xy = np.clip(point + offset, -lim, lim)
    z = base_z + 0.01 + np.cumsum(radius) + np.concatenate([[0.0], np.cumsum(radius[:-1])]) + 0.005 * np.arange(n)
    quat_xyzw = Rotation.random(n, random_state=rng).as_quat()
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
    from mqa_rl.sim.scene import add_object, add_sleeve, build_world, lift_sleeve

    chosen = [assets[i] for i in indices]
    drop_bin = BinSpec(bin_spec.inner_size, DROP_WALL_HEIGHT, bin_spec.wall_thickness)
    for attempt in range(1, MAX_ATTEMPTS + 1):
        world = build_world([], np.zeros((0, 7)), bin_spec=drop_bin)
        steps = 0
        point = rng.uniform(-DROP_POINT_RANGE, DROP_POINT_RANGE, 2)
        sleeve = add_sleeve(world, point, SLEEVE_SIZE, DROP_WALL_HEIGHT) if SLEEVE_SIZE else []
        for start in range(0, len(chosen), WAVE):
            wave = chosen[start:start + WAVE]
            for asset, pose in zip(wave, _column_poses(rng, wave, _pile_top(world), point, bin_spec)):
                add_object(world, asset, pose)
            world.step(WAVE_STEPS)
            steps += WAVE_STEPS
        if sleeve:
            steps += world.settle(MAX_SETTLE_STEPS)
            steps += lift_sleeve(world, sleeve, SLEEVE_LIFT_SPEED, _pile_top(world) + 0.05)
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


def drop_config() -> dict:
    """The pouring parameters, recorded in the dataset manifest."""
    return {"wave": WAVE, "wave_steps": WAVE_STEPS, "drop_spread": DROP_SPREAD, "drop_point_range": DROP_POINT_RANGE,
            "sleeve_size": SLEEVE_SIZE, "sleeve_lift_speed": SLEEVE_LIFT_SPEED}

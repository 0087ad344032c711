"""The fixed world of the MQA task: a square bin centred at the origin and a top-down camera.

World frame: z up, the bin floor at z = 0, the bin centred on the z axis. The camera looks straight
down; its image has **u (columns) along world +x and v (rows) along world −y**, so the picture reads
like a map (world +y is image up). Pixel (row r, col c) covers u ∈ [c, c+1), v ∈ [r, r+1): its centre
projects from the point with (u, v) = (c + 0.5, r + 0.5), the convention SAPIEN's renderer follows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


# The bin: a 40 × 40 cm tote with 45 cm walls (72 l). 20 / 35 / 50 real-size household objects
# laid flat would cover 1.5 / 2.6 / 3.8 times its floor, so they pile up and hide each other (the
# paper's premise); the measured trade-off against a 50 cm bin: docs/notebook/dataset.md.
BIN_INNER_SIZE = 0.40
BIN_WALL_HEIGHT = 0.45
# The camera: straight down from CAMERA_DISTANCE above the floor, its image framing the bin's RIM
# plus CAMERA_MARGIN on every side, so the top of a pile next to a wall is still in view and the
# 28 × 28 action grid is spent on the bin (the floor then spans ~72 % of the image).
CAMERA_DISTANCE = 2.0
CAMERA_MARGIN = 0.02


@dataclass(frozen=True)
class BinSpec:
    """A square open-top box. Objects are "in the bin" when their centre is inside the inner walls."""

    inner_size: float = BIN_INNER_SIZE     # inner side length along x and y (m)
    wall_height: float = BIN_WALL_HEIGHT   # (m)
    wall_thickness: float = 0.02           # (m)

    @property
    def half(self) -> float:
        return self.inner_size / 2

    def inside(self, positions: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether points [..., 3] lie within the inner walls (shrunk by ``margin``) and above the floor."""
        p = np.asarray(positions)
        lim = self.half - margin
        return (np.abs(p[..., 0]) <= lim) & (np.abs(p[..., 1]) <= lim) & (p[..., 2] > -0.01)


def framing_fovy(bin_spec: BinSpec, distance: float = CAMERA_DISTANCE, margin: float = CAMERA_MARGIN) -> float:
    """Vertical field of view (degrees) of a camera ``distance`` above the floor whose square image
    covers the bin's rim plus ``margin`` on each side."""
    return math.degrees(2 * math.atan((bin_spec.half + margin) / (distance - bin_spec.wall_height)))


@dataclass(frozen=True)
class CameraSpec:
    """A pinhole RGB-D camera above the bin centre, square pixels, principal point at the image centre.

    The paper used a Kinect fixed above the bin. The defaults frame the default bin's rim (see
    ``framing_fovy``); the image then covers ~0.55 m of the floor, so a push of a quarter image width
    (the paper's) is ~0.14 m on the floor.
    """

    width: int = 224
    height: int = 224
    fovy_deg: float = framing_fovy(BinSpec())
    distance: float = CAMERA_DISTANCE       # camera height above the bin floor (m)
    near: float = 0.1
    far: float = 2.5

    @property
    def fy(self) -> float:
        return (self.height / 2) / math.tan(math.radians(self.fovy_deg) / 2)

    @property
    def intrinsic(self) -> np.ndarray:
        """K (3×3), OpenCV convention."""
        f = self.fy
        return np.array([[f, 0.0, self.width / 2], [0.0, f, self.height / 2], [0.0, 0.0, 1.0]])

    @property
    def position(self) -> np.ndarray:
        return np.array([0.0, 0.0, self.distance])

    @property
    def rotation_world_to_cv(self) -> np.ndarray:
        """Rows are the OpenCV camera axes (x right, y down, z forward) in world coordinates."""
        return np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])

    @property
    def extrinsic(self) -> np.ndarray:
        """World → OpenCV camera, 3×4 (the same matrix SAPIEN's ``get_extrinsic_matrix`` returns)."""
        r = self.rotation_world_to_cv
        return np.concatenate([r, (-r @ self.position)[:, None]], axis=1)

    @property
    def sapien_quaternion(self) -> np.ndarray:
        """wxyz orientation of a SAPIEN camera entity (x forward, y left, z up) matching ``extrinsic``."""
        forward, left, up = np.array([0, 0, -1.0]), np.array([-1.0, 0, 0]), np.array([0, 1.0, 0])
        rot = np.stack([forward, left, up], axis=1)
        return matrix_to_wxyz(rot)

    def floor_width(self) -> float:
        """Width of the image footprint on the bin floor (m)."""
        return self.distance * self.width / self.fy

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points [..., 3] → (pixel coordinates [..., 2] as (u, v), depth along the view axis [...])."""
        p = np.asarray(points, dtype=np.float64)
        cam = p @ self.rotation_world_to_cv.T + self.extrinsic[:, 3]
        z = cam[..., 2]
        k = self.intrinsic
        u = k[0, 0] * cam[..., 0] / z + k[0, 2]
        v = k[1, 1] * cam[..., 1] / z + k[1, 2]
        return np.stack([u, v], axis=-1), z

    def unproject(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Pixel coordinates [..., 2] and depth [...] → world points [..., 3] (inverse of ``project``)."""
        uv = np.asarray(uv, dtype=np.float64)
        z = np.asarray(depth, dtype=np.float64)
        k = self.intrinsic
        cam = np.stack([(uv[..., 0] - k[0, 2]) * z / k[0, 0], (uv[..., 1] - k[1, 2]) * z / k[1, 1], z], -1)
        return (cam - self.extrinsic[:, 3]) @ self.rotation_world_to_cv


def matrix_to_wxyz(rot: np.ndarray) -> np.ndarray:
    """Rotation matrix → unit quaternion (w, x, y, z) with w ≥ 0."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(rot).as_quat()
    q = np.array([w, x, y, z])
    return q if q[0] >= 0 else -q


def wxyz_to_matrix(q: np.ndarray) -> np.ndarray:
    """Unit quaternions [..., 4] (w, x, y, z) → rotation matrices [..., 3, 3]."""
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )

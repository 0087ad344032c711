"""Complete projected silhouettes (the paper's A_t) without rendering.

An object is a union of convex parts; under a pinhole camera the image of a convex part is the
convex hull of its projected vertices, so the object's full silhouette (as if nothing occluded it) is
the union of those hulls. A pixel belongs to the silhouette when its centre (c + 0.5, r + 0.5) lies
inside a hull: the renderer's own rule, so the masks agree with an isolated render to IoU ≈ 1
(measured in tests/test_silhouette.py). Projection costs ~0.3 ms per object, a render ~10 ms.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from mqa_rl.sim.geometry import CameraSpec, wxyz_to_matrix


def convex_polygon_mask(points_uv: np.ndarray, height: int, width: int) -> tuple[slice, slice, np.ndarray] | None:
    """Rasterise the convex hull of 2-D points by the pixel-centre rule.

    Returns ``(rows, cols, mask)`` for the hull's bounding box clipped to the image, or None when the
    hull covers no pixel centre.
    """
    pts = np.asarray(points_uv, dtype=np.float64)
    try:
        hull = pts[ConvexHull(pts).vertices]          # counter-clockwise in (u, v)
    except (QhullError, ValueError):                   # degenerate (a line or a point): no area
        return None
    c0 = max(int(np.floor(hull[:, 0].min() - 0.5)), 0)
    c1 = min(int(np.ceil(hull[:, 0].max() - 0.5)), width - 1)
    r0 = max(int(np.floor(hull[:, 1].min() - 0.5)), 0)
    r1 = min(int(np.ceil(hull[:, 1].max() - 0.5)), height - 1)
    if c1 < c0 or r1 < r0:
        return None
    u = np.arange(c0, c1 + 1) + 0.5
    v = np.arange(r0, r1 + 1) + 0.5
    a = hull
    b = np.roll(hull, -1, axis=0)
    # inside ⇔ cross(b − a, p − a) ≥ 0 for every edge (CCW hull); separable in u and v
    ex, ey = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    cross = ex[:, None, None] * (v[None, :, None] - a[:, 1, None, None]) - ey[:, None, None] * (
        u[None, None, :] - a[:, 0, None, None]
    )
    mask = np.all(cross >= -1e-9, axis=0)
    return slice(r0, r1 + 1), slice(c0, c1 + 1), mask


def transform_points(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Object-frame points [n, 3] → world, with ``pose`` = (x, y, z, qw, qx, qy, qz)."""
    pose = np.asarray(pose, dtype=np.float64)
    return points @ wxyz_to_matrix(pose[3:7]).T + pose[:3]


def object_silhouette(parts: list[np.ndarray], pose: np.ndarray, camera: CameraSpec) -> np.ndarray:
    """Full silhouette [H, W] bool of one object given its convex parts' vertices (object frame)."""
    out = np.zeros((camera.height, camera.width), dtype=bool)
    for verts in parts:
        uv, z = camera.project(transform_points(verts, pose))
        if np.any(z <= camera.near):
            raise ValueError("object crosses the camera's near plane; it cannot be projected")
        box = convex_polygon_mask(uv, camera.height, camera.width)
        if box is not None:
            rows, cols, mask = box
            out[rows, cols] |= mask
    return out


def silhouettes(objects_parts: list[list[np.ndarray]], poses: np.ndarray, camera: CameraSpec) -> np.ndarray:
    """Full silhouettes [N, H, W] of N objects (their convex parts and poses [N, 7])."""
    out = np.zeros((len(objects_parts), camera.height, camera.width), dtype=bool)
    for i, (parts, pose) in enumerate(zip(objects_parts, poses)):
        out[i] = object_silhouette(parts, pose, camera)
    return out

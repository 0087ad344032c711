"""The building blocks of the object library (``mqa_rl.data.objects``): convex parts and the
primitive shape families they are made from.

Every helper returns one convex, watertight ``Part`` (or a few, for a ring), built as the convex hull
of a point cloud, so that one helper covers a whole family (cylinders, frustums and tapered handles
are all ``lathe``) and what the camera sees is exactly what the physics engine simulates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

RGBA = tuple[float, float, float, float]


@dataclass(frozen=True)
class Part:
    """One convex piece of an object: collision shape and visual at once."""

    mesh: trimesh.Trimesh  # convex, watertight, in the object's frame, metres
    color: RGBA  # RGBA in 0..1


# --------------------------------------------------------------------------------------
# Colours
# --------------------------------------------------------------------------------------


def rgb(hex_code: str) -> RGBA:
    """Opaque RGBA from a ``#rrggbb`` string; hex keeps the tables short and readable."""
    value = hex_code.lstrip("#")
    red, green, blue = (int(value[i : i + 2], 16) / 255.0 for i in (0, 2, 4))
    return (red, green, blue, 1.0)


STEEL = rgb("#aab2bd")
DARK_STEEL = rgb("#6c757d")
RUBBER = rgb("#1c1c1c")
BROWN = rgb("#5c3d1e")
LEAF_GREEN = rgb("#4f9d2d")
WHITE = rgb("#f4f4f0")
GLASS = rgb("#9cc9dd")

# --------------------------------------------------------------------------------------
# Primitive shape families.  Each helper returns point clouds positioned in the object's
# frame, and ``hull_part`` turns a point cloud into a convex, watertight part.  Working
# with points (rather than primitive meshes) lets one helper cover a whole family, e.g.
# cylinders, frustums and tapered handles.
# --------------------------------------------------------------------------------------

# A helper builds its shape along local z; these column orders rotate local z onto the
# requested world axis (cyclic permutations, hence proper rotations).
_AXIS_COLUMNS = {"z": [0, 1, 2], "x": [2, 0, 1], "y": [1, 2, 0]}


def pose(points: np.ndarray, center: Sequence[float] = (0.0, 0.0, 0.0), axis: str = "z") -> np.ndarray:
    """Rotate a shape built along local z onto world ``axis``, then move it to ``center``."""
    points = np.asarray(points, dtype=np.float64)[:, _AXIS_COLUMNS[axis]]
    return points + np.asarray(center, dtype=np.float64)


def hull_part(points: np.ndarray, color: RGBA) -> Part:
    """Convex hull of a point cloud as a part (convex and watertight by construction)."""
    mesh = trimesh.convex.convex_hull(np.asarray(points, dtype=np.float64))
    return Part(mesh=mesh, color=color)


def box(size: Sequence[float], color: RGBA, center=(0.0, 0.0, 0.0)) -> Part:
    """Rectangular block (book boards, labels, car body)."""
    corners = np.array(np.meshgrid([-0.5, 0.5], [-0.5, 0.5], [-0.5, 0.5])).reshape(3, -1).T
    return hull_part(pose(corners * np.asarray(size), center), color)


def rounded_box(
    size: Sequence[float],
    corner_radius: float,
    color: RGBA,
    center=(0.0, 0.0, 0.0),
    taper: float = 1.0,
) -> Part:
    """Block with rounded vertical edges (remotes, sponges); ``taper`` shrinks the top face."""
    length, width, height = size
    radius = min(corner_radius, 0.5 * min(length, width) - 1e-4)
    angles = np.linspace(0.0, 0.5 * np.pi, 5)
    arc = radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    outline = []
    for sign_x, sign_y in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
        corner = np.array([sign_x * (0.5 * length - radius), sign_y * (0.5 * width - radius)])
        outline.append(corner + arc * [sign_x, sign_y])
    outline = np.concatenate(outline)
    bottom = np.column_stack([outline, np.full(len(outline), -0.5 * height)])
    top = np.column_stack([outline * taper, np.full(len(outline), 0.5 * height)])
    return hull_part(pose(np.vstack([bottom, top]), center), color)


def lathe_points(stations: Sequence[tuple[float, float]], sections: int = 20) -> np.ndarray:
    """Circles of the given (position along z, radius) stations; their hull is a solid of revolution."""
    angles = np.linspace(0.0, 2.0 * np.pi, sections, endpoint=False)
    circle = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return np.vstack([np.column_stack([radius * circle, np.full(sections, z)]) for z, radius in stations])


def lathe(
    stations: Sequence[tuple[float, float]],
    color: RGBA,
    center=(0.0, 0.0, 0.0),
    axis: str = "z",
    sections: int = 20,
) -> Part:
    """Convex solid of revolution along ``axis`` (bottle shoulder, tapered shafts).

    The radius profile must be concave for the hull to match it, which holds for the
    cylinders, frustums and tapers used here.
    """
    return hull_part(pose(lathe_points(stations, sections), center, axis), color)


def cylinder(
    radius: float,
    length: float,
    color: RGBA,
    center=(0.0, 0.0, 0.0),
    axis: str = "z",
    end_radius: float | None = None,
    sections: int = 20,
) -> Part:
    """Cylinder along ``axis``; with ``end_radius`` a frustum whose +axis end has that radius."""
    end_radius = radius if end_radius is None else end_radius
    return lathe([(-0.5 * length, radius), (0.5 * length, end_radius)], color, center, axis, sections)


def ellipsoid_points(radii: Sequence[float], center=(0.0, 0.0, 0.0), subdivisions: int = 2) -> np.ndarray:
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions).vertices
    return sphere * np.asarray(radii, dtype=np.float64) + np.asarray(center, dtype=np.float64)


def ellipsoid(radii: Sequence[float], color: RGBA, center=(0.0, 0.0, 0.0)) -> Part:
    """Ellipsoid (balls, apples, duck body)."""
    return hull_part(ellipsoid_points(radii, center), color)


def blob(ends: Sequence[tuple[Sequence[float], Sequence[float]]], color: RGBA) -> Part:
    """Hull of several (center, radii) ellipsoids: capsules, tapered limbs, fruit segments."""
    points = [ellipsoid_points(radii, center, subdivisions=1) for center, radii in ends]
    return hull_part(np.vstack(points), color)


def ring(
    radii: Sequence[float],
    band: float,
    thickness: float,
    color: RGBA,
    center=(0.0, 0.0, 0.0),
    axis: str = "z",
    arc: tuple[float, float] = (0.0, 2.0 * np.pi),
    pieces: int = 4,
) -> list[Part]:
    """(Elliptic) annulus arc split into ``pieces`` convex sectors: loops, handles, shackles.

    The ring lies in the plane normal to ``axis``; ``radii`` are its outer half-axes and
    ``arc`` the covered angle range in that plane's local (u, v) coordinates.
    """
    outer = np.asarray(radii, dtype=np.float64)
    inner = outer - band
    bounds = np.linspace(arc[0], arc[1], pieces + 1)
    parts = []
    for start, stop in zip(bounds[:-1], bounds[1:]):
        angles = np.linspace(start, stop, 4)
        direction = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        outline = np.vstack([direction * outer, direction * inner])
        points = np.vstack(
            [
                np.column_stack([outline, np.full(len(outline), -0.5 * thickness)]),
                np.column_stack([outline, np.full(len(outline), 0.5 * thickness)]),
            ]
        )
        parts.append(hull_part(pose(points, center, axis), color))
    return parts


def prism(outline: Sequence[Sequence[float]], z_range: tuple[float, float], color: RGBA) -> Part:
    """Vertical extrusion of a 2-D outline (its convex hull is used): blades, wedges."""
    outline = np.asarray(outline, dtype=np.float64)
    points = np.vstack(
        [np.column_stack([outline, np.full(len(outline), z)]) for z in z_range]
    )
    return hull_part(points, color)

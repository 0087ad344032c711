"""Procedural library of household objects for the bin scenes.

The paper fills a bin with up to 50 everyday objects and asks questions about them
("How many cans are there in the bin?").  Instead of relying on scanned assets we build
every object from a handful of primitive shape families (``mqa_rl.data.object_parts``):

* Every object is a union of *convex* parts.  Each part is used both as the visual
  mesh and as a convex collision shape, so what the camera sees is exactly what the
  physics engine simulates (no convex-decomposition step, no hidden approximations).
  Irregular shapes (scissors, gamepad, mug handle, banana, ...) therefore use several
  overlapping convex pieces; no boolean mesh operations are needed.
* Everything is deterministic: each of the ``INSTANCES_PER_CLASS`` instances of a
  class comes from an explicit row of a parameter table below.  Instances of a class
  share a recognisable shape and differ in size, proportions and colour.
* Objects are modelled lying in their natural resting pose, z up, in metres, are
  re-centred so that the origin is the centre of their axis-aligned bounding box, and
  are scaled to real-world size (``mqa_rl.data.object_sizes``: the builders fix shape
  and proportions, the size table the longest side, with the product it comes from).

Only ``numpy`` and ``trimesh`` are used so that dataset tooling can import this module
without a simulator.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mqa_rl.data.object_parts import (
    RGBA,
    Part,
    STEEL,
    DARK_STEEL,
    RUBBER,
    BROWN,
    LEAF_GREEN,
    WHITE,
    GLASS,
    blob,
    box,
    cylinder,
    ellipsoid,
    hull_part,
    lathe,
    lathe_points,
    pose,
    prism,
    rgb,
    ring,
    rounded_box,
)
from mqa_rl.data.object_sizes import REAL_LENGTH

INSTANCES_PER_CLASS = 3


@dataclass(frozen=True)
class ObjectModel:
    """A rigid household object made of convex parts, centred on its bounding box."""

    class_name: str
    instance_id: int
    parts: tuple[Part, ...]
    density: float  # kg/m^3, applied uniformly to all parts

    @property
    def name(self) -> str:
        return f"{self.class_name}_{self.instance_id}"

    @property
    def volume(self) -> float:
        """Sum of the part volumes (overlaps are counted twice; they are small)."""
        return float(sum(part.mesh.volume for part in self.parts))

    @property
    def mass(self) -> float:
        return self.density * self.volume

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) array: min and max corner of the bounding box of all parts."""
        return _bounds(part.mesh for part in self.parts)

    @property
    def dimensions(self) -> np.ndarray:
        """Extents (x, y, z) of the axis-aligned bounding box of all parts."""
        lower, upper = self.bounds
        return upper - lower


# --------------------------------------------------------------------------------------
# Object classes.  Each builder takes one row of its parameter table and returns the parts
# in an arbitrary frame (usually resting on z = 0); ``make_object`` re-centres them.
# Small "decal" parts (labels, buttons) stick out 1-2 mm so that they are visible and do
# not z-fight with the surface they sit on.
# --------------------------------------------------------------------------------------

_CAN = (
    dict(radius=0.033, height=0.115, body=rgb("#c8102e")),  # 330 ml soda
    dict(radius=0.027, height=0.135, body=rgb("#1f4fa8")),  # slim energy drink
    dict(radius=0.037, height=0.080, body=rgb("#2e8b57")),  # short, wide food can
)


def _can(radius: float, height: float, body: RGBA) -> list[Part]:
    """Upright drink can: coloured body with inset silver lid and base."""
    lid_radius, lid_height = 0.86 * radius, 0.008
    return [
        cylinder(radius, height - 0.008, body, center=(0, 0, 0.5 * height), sections=24),
        cylinder(lid_radius, lid_height, STEEL, center=(0, 0, height - 0.5 * lid_height), sections=24),
        cylinder(lid_radius, lid_height, STEEL, center=(0, 0, 0.5 * lid_height), sections=24),
    ]


_FOOD_BOX = (
    dict(size=(0.140, 0.095, 0.040), body=rgb("#f28c28"), label=rgb("#fff4d6"), logo=rgb("#d62828")),  # cereal
    dict(size=(0.120, 0.065, 0.050), body=rgb("#e85d04"), label=rgb("#ffe066"), logo=rgb("#1d3557")),  # pasta
    dict(size=(0.095, 0.085, 0.035), body=rgb("#ffa62b"), label=rgb("#ffffff"), logo=rgb("#2a9d8f")),  # tea
)


def _food_box(size: Sequence[float], body: RGBA, label: RGBA, logo: RGBA) -> list[Part]:
    """Printed cardboard box lying on its largest face, with a logo and a label on both faces.

    Labelling both large faces keeps the box recognisable when it lands upside down.
    """
    length, width, height = size
    label_size = (0.55 * length, 0.75 * width, 0.004)
    face = 0.5 * height
    return [
        box(size, body),
        box(label_size, label, center=(-0.12 * length, 0, face - 0.001)),
        box(label_size, label, center=(-0.12 * length, 0, -face + 0.001)),
        cylinder(0.18 * width, 0.004, logo, center=(0.30 * length, 0, face)),
    ]


_BOOK = (
    dict(size=(0.120, 0.090, 0.020), cover=rgb("#1d3557"), pages=rgb("#f1e9d2"), title=rgb("#e9c46a")),
    dict(size=(0.140, 0.100, 0.028), cover=rgb("#7b1e28"), pages=rgb("#efe6cf"), title=rgb("#f1faee")),
    dict(size=(0.105, 0.075, 0.016), cover=rgb("#4a2c6d"), pages=rgb("#f4ecd8"), title=rgb("#ffd166")),
)


def _book(size: Sequence[float], cover: RGBA, pages: RGBA, title: RGBA) -> list[Part]:
    """Closed hardback lying flat: two boards and a spine around a slightly inset page block."""
    length, width, height = size
    board, overhang = 0.003, 0.002
    top = 0.5 * height - 0.5 * board
    return [
        box((length - 2 * overhang, width - board - overhang, height - 2 * board), pages,
             center=(0, 0.5 * (board - overhang), 0)),
        box((length, width, board), cover, center=(0, 0, top)),
        box((length, width, board), cover, center=(0, 0, -top)),
        box((length, board, height), cover, center=(0, -0.5 * width + 0.5 * board, 0)),
        box((0.45 * length, 0.5 * width, board + 0.002), title, center=(0.18 * length, 0.05 * width, top)),
    ]


_SCISSORS = (
    dict(blade_length=0.085, loop_radii=(0.023, 0.013), handle=rgb("#f77f00")),  # office scissors
    dict(blade_length=0.070, loop_radii=(0.019, 0.012), handle=rgb("#2b2d42")),  # general purpose
    dict(blade_length=0.050, loop_radii=(0.016, 0.015), handle=rgb("#7b2cbf")),  # kids' scissors
)


def _scissors(blade_length: float, loop_radii: Sequence[float], handle: RGBA) -> list[Part]:
    """Closed scissors lying flat: two crossing steel blades and two plastic finger loops.

    The blades point along +x from the pivot at the origin; each blade continues into the
    loop on the opposite side, as in real scissors.
    """
    loop_x, loop_y = -(0.008 + loop_radii[0]), loop_radii[1] + 0.001
    band, thickness = 0.0045, 0.012
    parts = []
    for side, z_range in ((1.0, (0.001, 0.0065)), (-1.0, (0.0055, 0.011))):
        grip_x = loop_x + loop_radii[0] - 0.5 * band
        outline = [
            (grip_x, side * loop_y + 0.004), (grip_x, side * loop_y - 0.004),
            (0.0, 0.0065), (0.0, -0.0065),
            (blade_length, -side * 0.0005), (blade_length, -side * 0.0030),
        ]
        parts.append(prism(outline, z_range, STEEL))
        parts += ring(loop_radii, band, thickness, handle, center=(loop_x, side * loop_y, 0.006))
    return parts


_GAMEPAD = (
    dict(size=(0.100, 0.052, 0.024), body=rgb("#eeeeee"), sticks=rgb("#3a3a3a")),
    dict(size=(0.094, 0.048, 0.022), body=rgb("#2b2b2b"), sticks=rgb("#6b6b6b")),
    dict(size=(0.088, 0.050, 0.026), body=rgb("#3f5fbf"), sticks=rgb("#1c1c1c")),
)
_FACE_BUTTONS = (  # (dx, dy, colour) around the button cluster, like an Xbox pad
    (0.0, 1.0, rgb("#ffd60a")),
    (1.0, 0.0, rgb("#e63946")),
    (0.0, -1.0, rgb("#2dc653")),
    (-1.0, 0.0, rgb("#3a86ff")),
)


def _gamepad(size: Sequence[float], body: RGBA, sticks: RGBA) -> list[Part]:
    """Game controller lying face up: body, two grips, two sticks, d-pad and four buttons."""
    length, width, height = size
    grip_radius = (0.17 * length, 0.17 * length, 0.5 * height)
    parts = [rounded_box(size, 0.012, body, center=(0, 0, 0.5 * height), taper=0.96)]
    for side in (-1.0, 1.0):
        parts.append(blob([
            ((side * 0.33 * length, 0.0, 0.5 * height), grip_radius),
            ((side * 0.44 * length, -0.70 * width, 0.5 * height), grip_radius),
        ], body))
    stick_radius = 0.085 * length
    parts.append(cylinder(stick_radius, 0.008, sticks, center=(-0.30 * length, 0.10 * width, height + 0.003)))
    parts.append(cylinder(stick_radius, 0.008, sticks, center=(0.15 * length, -0.25 * width, height + 0.003)))
    dpad_center = (-0.15 * length, -0.25 * width, height)
    dpad_arm = 0.17 * length
    parts.append(box((dpad_arm, 0.06 * length, 0.006), sticks, center=dpad_center))
    parts.append(box((0.06 * length, dpad_arm, 0.006), sticks, center=dpad_center))
    spacing = 0.075 * length
    for dx, dy, color in _FACE_BUTTONS:
        center = (0.30 * length + dx * spacing, 0.10 * width + dy * spacing, height)
        parts.append(cylinder(0.032 * length, 0.006, color, center=center, sections=16))
    return parts


_BOTTLE = (
    dict(radius=0.028, body_length=0.085, body=rgb("#a8dadc"), label=rgb("#1d70b8"), cap=rgb("#f8f9fa")),
    dict(radius=0.025, body_length=0.090, body=rgb("#b7e4c7"), label=rgb("#d62828"), cap=rgb("#2d6a4f")),
    dict(radius=0.032, body_length=0.072, body=rgb("#cde8f6"), label=rgb("#f4a261"), cap=rgb("#e63946")),
)


def _bottle(radius: float, body_length: float, body: RGBA, label: RGBA, cap: RGBA) -> list[Part]:
    """Plastic bottle lying on its side along x: body with a label band, shoulder and neck, cap."""
    neck_radius, shoulder_length, neck_length, cap_length = 0.012, 0.025, 0.012, 0.014
    neck_end = body_length + shoulder_length + neck_length
    label_start, label_end = 0.25 * body_length, 0.75 * body_length
    return [
        cylinder(radius, label_start, body, center=(0.5 * label_start, 0, 0), axis="x"),
        cylinder(radius + 0.001, label_end - label_start, label, center=(0.5 * (label_start + label_end), 0, 0),
                  axis="x"),
        cylinder(radius, body_length - label_end, body, center=(0.5 * (label_end + body_length), 0, 0), axis="x"),
        lathe([(body_length - 0.002, radius), (body_length + shoulder_length, neck_radius),
               (neck_end, neck_radius)], body, axis="x"),
        cylinder(neck_radius + 0.0025, cap_length, cap, center=(neck_end - 0.004 + 0.5 * cap_length, 0, 0),
                  axis="x", sections=16),
    ]


_MUG = (
    dict(radius=0.040, height=0.090, body=rgb("#f8f9fa"), glaze=rgb("#c1121f")),
    dict(radius=0.036, height=0.100, body=rgb("#fdf0d5"), glaze=rgb("#1d4e89")),
    dict(radius=0.043, height=0.078, body=rgb("#e9ecef"), glaze=rgb("#2a9d8f")),
)


def _mug(radius: float, height: float, body: RGBA, glaze: RGBA) -> list[Part]:
    """Upright mug: white body, coloured interior seen from above, and a coloured handle.

    The interior is a disc just above the rim, since a convex body cannot be hollow.
    """
    handle_radius = 0.30 * height
    parts = [
        cylinder(radius, height, body, center=(0, 0, 0.5 * height), sections=24),
        cylinder(0.84 * radius, 0.004, glaze, center=(0, 0, height), sections=24),
    ]
    # Half ring in the xz plane on the +x side; axis "y" maps local (u, v) to world (z, x).
    parts += ring((handle_radius, handle_radius), 0.009, 0.013, glaze,
                   center=(radius - 0.004, 0, 0.5 * height), axis="y", arc=(0.0, np.pi), pieces=3)
    return parts


_BOWL = (
    dict(radius=0.065, height=0.048, outside=rgb("#1d3557"), inside=rgb("#f1faee")),
    dict(radius=0.058, height=0.055, outside=rgb("#457b9d"), inside=rgb("#fefae0")),
    dict(radius=0.070, height=0.040, outside=rgb("#0077b6"), inside=rgb("#dbe9f4")),
)


def _bowl(radius: float, height: float, outside: RGBA, inside: RGBA) -> list[Part]:
    """Glazed bowl: flared body on a foot ring, with a light interior disc at the rim."""
    foot_radius, foot_height = 0.48 * radius, 0.006
    return [
        cylinder(foot_radius, foot_height, outside, center=(0, 0, 0.5 * foot_height), sections=24),
        cylinder(0.56 * radius, height - foot_height + 0.002, outside, end_radius=radius,
                  center=(0, 0, 0.5 * (height + foot_height) - 0.001), sections=24),
        cylinder(0.87 * radius, 0.004, inside, center=(0, 0, height), sections=24),
    ]


_BANANA = (
    dict(arc_length=0.128, radius=0.018, bend=1.00, peel=rgb("#f7d12e")),
    dict(arc_length=0.118, radius=0.017, bend=0.75, peel=rgb("#d9e24a")),  # not quite ripe
    dict(arc_length=0.105, radius=0.016, bend=1.25, peel=rgb("#f4b81c")),  # very ripe
)
_BANANA_PROFILE = (0.45, 1.0, 0.95, 0.45)  # radius along the fruit, stem end first


def _banana(arc_length: float, radius: float, bend: float, peel: RGBA) -> list[Part]:
    """Banana lying flat: a curved chain of tapered segments plus stem and blossom tip."""
    bend_radius = arc_length / bend
    angles = np.linspace(-0.5 * bend, 0.5 * bend, len(_BANANA_PROFILE))
    spine = np.stack([bend_radius * np.sin(angles), bend_radius * (np.cos(angles) - 1.0),
                      np.zeros_like(angles)], axis=1)
    radii = [(s * radius, s * radius, 0.85 * s * radius) for s in _BANANA_PROFILE]
    parts = [blob([(spine[i], radii[i]), (spine[i + 1], radii[i + 1])], peel) for i in range(len(spine) - 1)]
    # Stem: continues the curve beyond the first point, thinner and greenish brown.
    stem_direction = spine[0] - spine[1]
    stem_end = spine[0] + 0.015 * stem_direction / np.linalg.norm(stem_direction)
    stem_radius = (0.004, 0.004, 0.004)
    parts.append(blob([(spine[0], stem_radius), (stem_end, stem_radius)], rgb("#6b5d2e")))
    parts.append(ellipsoid((0.005, 0.005, 0.005), BROWN, center=spine[-1]))
    return parts


_APPLE = (
    dict(radius=0.038, height=0.070, skin=rgb("#c1121f")),
    dict(radius=0.034, height=0.064, skin=rgb("#8d0801")),
    dict(radius=0.041, height=0.074, skin=rgb("#e5383b")),
)


def _apple(radius: float, height: float, skin: RGBA) -> list[Part]:
    """Apple: slightly squashed sphere with a brown stem and a green leaf on top."""
    return [
        ellipsoid((radius, radius, 0.5 * height), skin, center=(0, 0, 0.5 * height)),
        cylinder(0.0035, 0.014, BROWN, center=(0, 0, height + 0.002), sections=12),
        ellipsoid((0.013, 0.0065, 0.0025), LEAF_GREEN, center=(0.011, 0.004, height - 0.0015)),
    ]


_TENNIS_BALL = (
    dict(radius=0.0335, felt=rgb("#dfff4f")),  # new ball, optic yellow
    dict(radius=0.0320, felt=rgb("#c5e03a")),  # worn ball
    dict(radius=0.0300, felt=rgb("#eef76b")),  # junior ball
)


def _tennis_ball(radius: float, felt: RGBA) -> list[Part]:
    """Tennis ball: a single felt sphere."""
    return [ellipsoid((radius, radius, radius), felt)]


_MARKER = (
    dict(radius=0.0095, length=0.135, ink=rgb("#1b1b1b")),
    dict(radius=0.0080, length=0.125, ink=rgb("#d62828")),
    dict(radius=0.0110, length=0.115, ink=rgb("#1d4ed8")),
)


def _marker(radius: float, length: float, ink: RGBA) -> list[Part]:
    """Felt-tip marker lying along x: white barrel, cap and end plug in the ink colour."""
    cap_length = 0.32 * length
    barrel_length = length - cap_length + 0.002
    return [
        cylinder(radius, barrel_length, WHITE, center=(0.5 * barrel_length, 0, 0), axis="x", sections=16),
        cylinder(radius + 0.001, cap_length, ink, center=(length - 0.5 * cap_length, 0, 0), axis="x", sections=16),
        cylinder(0.8 * radius, 0.006, ink, center=(0.002, 0, 0), axis="x", sections=16),
    ]


_REMOTE_CONTROL = (
    dict(size=(0.140, 0.045, 0.020), body=rgb("#1f1f1f"), keys=rgb("#5c5c5c")),
    dict(size=(0.150, 0.040, 0.018), body=rgb("#3a3d40"), keys=rgb("#8d9196")),
    dict(size=(0.120, 0.050, 0.022), body=rgb("#2f3e46"), keys=rgb("#cad2c5")),
)


def _remote_control(size: Sequence[float], body: RGBA, keys: RGBA) -> list[Part]:
    """TV remote lying face up: dark body, red power button, navigation disc, keypad panel."""
    length, width, height = size
    top = 0.5 * height
    return [
        rounded_box(size, 0.012, body, taper=0.95),
        cylinder(0.0045, 0.004, rgb("#d62828"), center=(0.5 * length - 0.013, -0.22 * width, top), sections=16),
        cylinder(0.28 * width, 0.004, keys, center=(0.18 * length, 0, top)),
        rounded_box((0.40 * length, 0.62 * width, 0.004), 0.004, keys, center=(-0.20 * length, 0, top)),
    ]


_TOY_CAR = (
    dict(length=0.100, width=0.046, body_height=0.016, cabin=(0.40, 0.014), paint=rgb("#d62828")),  # sports car
    dict(length=0.090, width=0.044, body_height=0.020, cabin=(0.52, 0.017), paint=rgb("#ffb703")),  # taxi
    dict(length=0.085, width=0.048, body_height=0.022, cabin=(0.75, 0.022), paint=rgb("#1d70b8")),  # van
)


def _toy_car(length: float, width: float, body_height: float, cabin: tuple[float, float],
             paint: RGBA) -> list[Part]:
    """Toy car: painted body, glass cabin with painted roof, four black wheels.

    ``cabin`` is (cabin length as a fraction of the car length, cabin height).
    """
    cabin_fraction, cabin_height = cabin
    wheel_radius, wheel_width = 0.011, 0.009
    body_bottom = 0.55 * wheel_radius
    body_top = body_bottom + body_height
    cabin_length = cabin_fraction * length
    cabin_x = -0.06 * length if cabin_fraction < 0.7 else -0.12 * length
    cabin_outline = np.array([
        (-0.5 * cabin_length, -0.5 * width + 0.003), (0.5 * cabin_length, -0.5 * width + 0.003),
        (0.5 * cabin_length, 0.5 * width - 0.003), (-0.5 * cabin_length, 0.5 * width - 0.003),
    ])
    cabin_points = np.vstack([
        np.column_stack([cabin_outline, np.full(4, body_top - 0.002)]),
        np.column_stack([cabin_outline * (0.75, 0.85), np.full(4, body_top + cabin_height)]),
    ]) + (cabin_x, 0, 0)
    roof_size = (0.75 * cabin_length - 0.006, 0.85 * (width - 0.006) - 0.004, 0.004)
    parts = [
        rounded_box((length, width, body_height), 0.008, paint, center=(0, 0, body_bottom + 0.5 * body_height)),
        hull_part(cabin_points, GLASS),
        box(roof_size, paint, center=(cabin_x, 0, body_top + cabin_height)),
    ]
    for x in (-0.32 * length, 0.32 * length):
        for side in (-1.0, 1.0):
            center = (x, side * (0.5 * width - 0.5 * wheel_width + 0.002), wheel_radius)
            parts.append(cylinder(wheel_radius, wheel_width, RUBBER, center=center, axis="y", sections=16))
    return parts


_SCREWDRIVER = (
    dict(length=0.150, handle_length=0.060, handle_radius=0.014, handle=rgb("#c1121f"), tip="flat"),
    dict(length=0.130, handle_length=0.055, handle_radius=0.013, handle=rgb("#ffc300"), tip="cross"),
    dict(length=0.100, handle_length=0.050, handle_radius=0.016, handle=rgb("#0077b6"), tip="flat"),  # stubby
)


def _screwdriver(length: float, handle_length: float, handle_radius: float, handle: RGBA,
                 tip: str) -> list[Part]:
    """Screwdriver lying along x: rubber end cap, tapered handle, steel shaft with tip."""
    shaft_radius, cap_length = 0.004, 0.014
    shaft_start = handle_length - 0.005
    tip_start = length - 0.010
    shaft = pose(lathe_points([(shaft_start, shaft_radius), (tip_start, shaft_radius)], sections=12), axis="x")
    if tip == "flat":  # wedge flattening to a 9 x 1.5 mm blade
        tip_points = np.array([[length, y, z] for y in (-0.0045, 0.0045) for z in (-0.00075, 0.00075)])
    else:  # cross head: cone to a blunt point
        tip_points = pose(lathe_points([(length, 0.0008)], sections=8), axis="x")
    return [
        cylinder(0.85 * handle_radius, cap_length, RUBBER, end_radius=handle_radius,
                  center=(0.5 * cap_length, 0, 0), axis="x", sections=16),
        cylinder(handle_radius, handle_length - cap_length + 0.002, handle, end_radius=0.75 * handle_radius,
                  center=(0.5 * (handle_length + cap_length) - 0.001, 0, 0), axis="x", sections=8),
        hull_part(np.vstack([shaft, tip_points]), STEEL),
    ]


_HAMMER = (
    dict(length=0.150, head_length=0.062, handle=rgb("#c08552"), grip=None),  # wooden handle
    dict(length=0.135, head_length=0.056, handle=rgb("#ffb703"), grip=rgb("#222222")),  # fibreglass
    dict(length=0.120, head_length=0.050, handle=rgb("#c1121f"), grip=rgb("#333333")),
)


def _hammer(length: float, head_length: float, handle: RGBA, grip: RGBA | None) -> list[Part]:
    """Claw hammer lying flat: handle along x, steel head across it (face +y, claw -y)."""
    head_radius = 0.011
    head_x = length - head_radius
    grip_length = 0.0 if grip is None else 0.42 * length
    handle_start, handle_end = max(grip_length - 0.002, 0.0), length - 0.004
    parts = [rounded_box((handle_end - handle_start, 0.016, 0.013), 0.005, handle,
                          center=(0.5 * (handle_start + handle_end), 0, 0))]
    if grip is not None:
        parts.append(rounded_box((grip_length, 0.019, 0.016), 0.006, grip, center=(0.5 * grip_length, 0, 0)))
    face_length = 0.45 * head_length
    parts.append(cylinder(head_radius, face_length + head_radius, STEEL,
                           center=(head_x, 0.5 * (face_length - head_radius), 0), axis="y", sections=16))
    claw_tip_y = -(head_length - face_length)
    claw_points = np.array([
        [head_x - head_radius, 0.0, -head_radius], [head_x + head_radius, 0.0, -head_radius],
        [head_x - head_radius, 0.0, head_radius], [head_x + head_radius, 0.0, head_radius],
        [head_x - 1.3 * head_radius, claw_tip_y, -0.004], [head_x - 0.7 * head_radius, claw_tip_y, -0.004],
        [head_x - 1.3 * head_radius, claw_tip_y, 0.004], [head_x - 0.7 * head_radius, claw_tip_y, 0.004],
    ])
    parts.append(hull_part(claw_points, DARK_STEEL))
    return parts


_SPOON = (
    dict(length=0.145, bowl=(0.025, 0.018), metal=rgb("#c0c4c8")),  # table spoon
    dict(length=0.130, bowl=(0.021, 0.015), metal=rgb("#9aa4ae")),  # dessert spoon
    dict(length=0.118, bowl=(0.022, 0.019), metal=rgb("#d4af37")),  # gilded soup spoon
)


def _spoon(length: float, bowl: tuple[float, float], metal: RGBA) -> list[Part]:
    """Spoon lying bowl-up: flattened ellipsoidal bowl and a handle widening to an oval end."""
    bowl_half_length, bowl_half_width = bowl
    end_x = bowl_half_length - length  # far end of the handle
    thickness = 0.007
    handle = blob([
        ((-0.6 * bowl_half_length, 0.0, 0.010), (0.005, 0.005, 0.5 * thickness)),
        ((end_x + 0.012, 0.0, 0.010), (0.012, 0.009, 0.5 * thickness)),
    ], metal)
    return [ellipsoid((bowl_half_length, bowl_half_width, 0.007), metal, center=(0, 0, 0.007)), handle]


_SPONGE = (
    dict(size=(0.100, 0.068, 0.030), foam=rgb("#ffd23f"), scrub=rgb("#2d6a4f")),
    dict(size=(0.090, 0.060, 0.026), foam=rgb("#ffe873"), scrub=rgb("#52b788")),
    dict(size=(0.078, 0.054, 0.034), foam=rgb("#f9a03f"), scrub=rgb("#1b4332")),
)


def _sponge(size: Sequence[float], foam: RGBA, scrub: RGBA) -> list[Part]:
    """Kitchen sponge: foam block with a green scouring layer on top."""
    length, width, height = size
    scrub_height = 0.008
    foam_height = height - scrub_height
    return [
        rounded_box((length, width, foam_height + 0.001), 0.006, foam, center=(0, 0, 0.5 * foam_height)),
        rounded_box((length - 0.006, width - 0.006, scrub_height), 0.005, scrub,
                     center=(0, 0, foam_height + 0.5 * scrub_height)),
    ]


_RUBBER_DUCK = (
    dict(scale=1.00, body=rgb("#ffd60a"), beak=rgb("#f77f00")),
    dict(scale=0.85, body=rgb("#ffe55c"), beak=rgb("#fb8500")),
    dict(scale=1.15, body=rgb("#f9c80e"), beak=rgb("#e85d04")),
)


def _rubber_duck(scale: float, body: RGBA, beak: RGBA) -> list[Part]:
    """Upright rubber duck facing +x: body, tail, head, beak and two black eyes."""
    def at(*xyz: float) -> np.ndarray:
        return scale * np.array(xyz)

    parts = [
        ellipsoid(at(0.040, 0.030, 0.022), body, center=at(0.0, 0.0, 0.022)),
        blob([(at(-0.026, 0.0, 0.026), at(0.012, 0.014, 0.012)), (at(-0.044, 0.0, 0.040), at(0.005, 0.006, 0.005))],
              body),
        ellipsoid(at(0.020, 0.020, 0.019), body, center=at(0.018, 0.0, 0.052)),
        ellipsoid(at(0.012, 0.010, 0.0045), beak, center=at(0.039, 0.0, 0.048)),
    ]
    for side in (-1.0, 1.0):
        parts.append(ellipsoid(at(0.0035, 0.0035, 0.0035), RUBBER, center=at(0.030, side * 0.012, 0.058)))
    return parts


_PADLOCK = (
    dict(body_size=(0.040, 0.034, 0.018), body=rgb("#c9a227")),  # brass
    dict(body_size=(0.050, 0.040, 0.022), body=rgb("#5a6169")),  # laminated steel
    dict(body_size=(0.032, 0.028, 0.016), body=rgb("#d1495b")),  # anodised aluminium
)


def _padlock(body_size: Sequence[float], body: RGBA) -> list[Part]:
    """Padlock lying flat: body with a steel U shackle (two legs and an arch) towards +y."""
    width, length, thickness = body_size
    bar, bar_thickness = 0.007, 0.009
    arch_radius = 0.5 * width - 0.006
    leg_length = 0.35 * length
    leg_y0 = 0.5 * length - 0.004
    arch_y = 0.5 * length + leg_length
    parts = [rounded_box(body_size, 0.004, body, taper=0.96)]
    for side in (-1.0, 1.0):
        parts.append(box((bar, arch_y - leg_y0, bar_thickness), STEEL,
                          center=(side * (arch_radius - 0.5 * bar), 0.5 * (leg_y0 + arch_y), 0)))
    parts += ring((arch_radius, arch_radius), bar, bar_thickness, STEEL, center=(0, arch_y, 0),
                   arc=(0.0, np.pi), pieces=3)
    return parts


# --------------------------------------------------------------------------------------
# Registry
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _ClassSpec:
    builder: Callable[..., list[Part]]
    density: float  # kg/m^3; hollow objects get a low density since they are modelled solid
    instances: tuple[dict[str, Any], ...]
    phrases: tuple[str, str]  # (singular with article, plural)


_SPECS: dict[str, _ClassSpec] = {
    "can": _ClassSpec(_can, 550.0, _CAN, ("a can", "cans")),
    "food_box": _ClassSpec(_food_box, 250.0, _FOOD_BOX, ("a food box", "food boxes")),
    "book": _ClassSpec(_book, 700.0, _BOOK, ("a book", "books")),
    "scissors": _ClassSpec(_scissors, 1200.0, _SCISSORS, ("a pair of scissors", "scissors")),
    "gamepad": _ClassSpec(_gamepad, 550.0, _GAMEPAD, ("a gamepad", "gamepads")),
    "bottle": _ClassSpec(_bottle, 400.0, _BOTTLE, ("a bottle", "bottles")),
    "mug": _ClassSpec(_mug, 600.0, _MUG, ("a mug", "mugs")),
    "bowl": _ClassSpec(_bowl, 500.0, _BOWL, ("a bowl", "bowls")),
    "banana": _ClassSpec(_banana, 900.0, _BANANA, ("a banana", "bananas")),
    "apple": _ClassSpec(_apple, 800.0, _APPLE, ("an apple", "apples")),
    "tennis_ball": _ClassSpec(_tennis_ball, 370.0, _TENNIS_BALL, ("a tennis ball", "tennis balls")),
    "marker": _ClassSpec(_marker, 400.0, _MARKER, ("a marker", "markers")),
    "remote_control": _ClassSpec(_remote_control, 800.0, _REMOTE_CONTROL, ("a remote control", "remote controls")),
    "toy_car": _ClassSpec(_toy_car, 700.0, _TOY_CAR, ("a toy car", "toy cars")),
    "screwdriver": _ClassSpec(_screwdriver, 1200.0, _SCREWDRIVER, ("a screwdriver", "screwdrivers")),
    "hammer": _ClassSpec(_hammer, 1500.0, _HAMMER, ("a hammer", "hammers")),
    "spoon": _ClassSpec(_spoon, 1500.0, _SPOON, ("a spoon", "spoons")),
    "sponge": _ClassSpec(_sponge, 200.0, _SPONGE, ("a sponge", "sponges")),
    "rubber_duck": _ClassSpec(_rubber_duck, 300.0, _RUBBER_DUCK, ("a rubber duck", "rubber ducks")),
    "padlock": _ClassSpec(_padlock, 1500.0, _PADLOCK, ("a padlock", "padlocks")),
}

CLASS_NAMES: tuple[str, ...] = tuple(_SPECS)
CLASS_PHRASES: dict[str, tuple[str, str]] = {name: spec.phrases for name, spec in _SPECS.items()}

assert all(len(spec.instances) == INSTANCES_PER_CLASS for spec in _SPECS.values())
assert set(REAL_LENGTH) == set(_SPECS) and all(len(v) == INSTANCES_PER_CLASS for v in REAL_LENGTH.values())


def _bounds(meshes) -> np.ndarray:
    corners = np.array([mesh.bounds for mesh in meshes])
    return np.array([corners[:, 0].min(axis=0), corners[:, 1].max(axis=0)])


def make_object(class_name: str, instance_id: int) -> ObjectModel:
    """Build one instance of a class, re-centred on its bounding box and scaled to its real size
    (longest side from ``mqa_rl.data.object_sizes.REAL_LENGTH``)."""
    if class_name not in _SPECS:
        raise ValueError(f"unknown object class {class_name!r}; expected one of: {', '.join(CLASS_NAMES)}")
    valid_id = isinstance(instance_id, (int, np.integer)) and not isinstance(instance_id, bool)
    if not valid_id or not 0 <= instance_id < INSTANCES_PER_CLASS:
        raise ValueError(
            f"instance_id for {class_name!r} must be one of {list(range(INSTANCES_PER_CLASS))}, got {instance_id!r}"
        )
    spec = _SPECS[class_name]
    parts = spec.builder(**spec.instances[int(instance_id)])
    lower, upper = _bounds(part.mesh for part in parts)
    scale = REAL_LENGTH[class_name][int(instance_id)][0] / float((upper - lower).max())
    for part in parts:
        part.mesh.apply_translation(-(lower + upper) / 2)
        part.mesh.apply_scale(scale)
    return ObjectModel(class_name=class_name, instance_id=int(instance_id), parts=tuple(parts),
                       density=spec.density)


def make_library() -> list[ObjectModel]:
    """All classes x instances, ordered by ``CLASS_NAMES`` then instance id."""
    return [make_object(name, i) for name in CLASS_NAMES for i in range(INSTANCES_PER_CLASS)]

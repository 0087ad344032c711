"""The Franka Panda with a long pushing stick, loaded from the ``mani_skill`` package's assets.

Why a long stick: the bin's walls are 45 cm high and piles reach ~35 cm, so a stock stick (10 cm
past the hand) would drag the 20 cm wide hand through the pile on every floor-level push. The tool
here is the stock stick of ``panda_stick.urdf`` (radius 8 mm, starting 5 cm below the hand frame)
lengthened to end ``TOOL_LENGTH`` below the hand frame, with a rounded tip: with the tip on the
floor the hand's lowest point is still 3.4 cm above the wall top, so only the stick enters the bin
(at 0.52 m, 7 mm above it, the 20 cm wide hand grazed a wall top when clutter tilted the stick).

Why this mount: the base stands on a pedestal beside the bin's −x wall, its top 3 cm above the wall
top; every tip position over the bin floor, from the floor to above the wall top, is reachable with
the stick vertical (every push of the 28 × 28 × 8 action grid at the floor, 35 cm and the wall top:
``benchmarks/arm_pusher.py reach``; with the base 3 cm lower, level with the wall top, 84-93 % of a
coarse subset). The robot files are read from the installed package, never copied.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import sapien

from mqa_rl.sim.scene import CONTACT_OFFSET

URDF_IN_PACKAGE = "assets/robots/panda/panda_stick.urdf"
INSTALL_HINT = "pip install 'mqa_rl[arm]'  (or: pip install --no-deps mani_skill==3.0.1; only its asset files are used)"

BASE_POSITION = np.array([-0.50, 0.0, 0.48])   # world (m): 28 cm beyond the −x wall's outer face, 3 cm above the wall top
PEDESTAL_HALF_SIZE = np.array([0.12, 0.12, 0.24])    # a 24 × 24 × 48 cm column under the base
TOOL_RADIUS = 0.008                             # the stock stick's radius (m)
TOOL_START = 0.05                               # the stock stick starts 5 cm below the hand frame (m)
TOOL_LENGTH = 0.55                              # hand frame → tool tip (m); hand's lowest point is 6.6 cm below the frame
HAND_LINK = "panda_hand"
JOINT_TORQUE_LIMITS = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)   # N·m, the URDF's efforts (Franka's datasheet)
TOOL_COLOR = (0.15, 0.15, 0.15, 1.0)
PEDESTAL_COLOR = (0.30, 0.30, 0.32, 1.0)
ARM_DENSITY = 1000.0


class ArmAssetsMissing(ImportError):
    """The optional ``mani_skill`` package (the robot's asset files) is not installed."""


def panda_urdf_path() -> Path:
    """Path of ``panda_stick.urdf`` inside the installed ``mani_skill`` package (found without importing
    it: only its asset files are needed, not its Python dependencies)."""
    spec = importlib.util.find_spec("mani_skill")
    if spec is None or not spec.submodule_search_locations:
        raise ArmAssetsMissing(f"the arm pusher needs the Panda robot assets of the 'mani_skill' package, which is not "
                               f"installed. Install it with: {INSTALL_HINT}")
    path = Path(list(spec.submodule_search_locations)[0]) / URDF_IN_PACKAGE
    if not path.is_file():
        raise ArmAssetsMissing(f"the installed 'mani_skill' package has no {URDF_IN_PACKAGE} (looked at {path}); "
                               f"install a version that ships it: {INSTALL_HINT}")
    return path


def _lengthen_stick(hand: "sapien.wrapper.articulation_builder.LinkBuilder", render: bool) -> None:
    """Replace the stock 10 cm stick of the hand link by a capsule of the same radius from TOOL_START to
    TOOL_LENGTH (the capsule's axis is x in PhysX: rotate it onto the hand's z axis)."""
    hand.collision_records = [r for r in hand.collision_records if r.type != "cylinder"]
    hand.visual_records = [r for r in hand.visual_records if r.type != "cylinder"]
    half = (TOOL_LENGTH - TOOL_START - TOOL_RADIUS) / 2
    pose = sapien.Pose([0, 0, TOOL_START + half], [0.7071068, 0, 0.7071068, 0])
    material = sapien.physx.PhysxMaterial(0.3, 0.3, 0.0)
    hand.add_capsule_collision(pose, TOOL_RADIUS, half, material=material, density=ARM_DENSITY)
    if render:
        hand.add_capsule_visual(pose, TOOL_RADIUS, half, sapien.render.RenderMaterial(base_color=list(TOOL_COLOR)))


def build_panda(scene: sapien.Scene, render: bool) -> tuple[sapien.physx.PhysxArticulation, sapien.Entity]:
    """The Panda with the long stick, fixed at ``BASE_POSITION``, gravity off on every link (a real Panda
    compensates gravity in its controller), and its pedestal. Visual meshes only when ``render``."""
    loader = scene.create_urdf_loader()
    loader.fix_root_link = True
    loader.set_density(ARM_DENSITY)
    builder = loader.load_file_as_articulation_builder(str(panda_urdf_path()))
    for link in builder.link_builders:
        if not render:
            link.visual_records = []
        if link.name == HAND_LINK:
            _lengthen_stick(link, render)
    builder.set_initial_pose(sapien.Pose(BASE_POSITION.astype(np.float32)))
    robot = builder.build(fix_root_link=True)
    robot.name = "panda"
    for link in robot.links:
        link.disable_gravity = True
        for shape in link.collision_shapes:
            shape.contact_offset = CONTACT_OFFSET
    return robot, _pedestal(scene, render)


def _pedestal(scene: sapien.Scene, render: bool) -> sapien.Entity:
    entity = sapien.Entity()
    entity.name = "pedestal"
    body = sapien.physx.PhysxRigidStaticComponent()
    shape = sapien.physx.PhysxCollisionShapeBox(PEDESTAL_HALF_SIZE.astype(np.float32), sapien.physx.PhysxMaterial(0.6, 0.5, 0.0))
    shape.contact_offset = CONTACT_OFFSET
    body.attach(shape)
    entity.add_component(body)
    if render:
        rb = sapien.render.RenderBodyComponent()
        rb.attach(sapien.render.RenderShapeBox(PEDESTAL_HALF_SIZE.astype(np.float32),
                                               sapien.render.RenderMaterial(base_color=list(PEDESTAL_COLOR))))
        entity.add_component(rb)
    entity.pose = sapien.Pose(np.array([BASE_POSITION[0], BASE_POSITION[1], PEDESTAL_HALF_SIZE[2]], np.float32))
    scene.add_entity(entity)
    return entity

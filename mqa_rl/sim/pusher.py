"""The push primitive, behind a small interface (``Pusher``): this finger, or the arm of ``arm_pusher``.

``FingerPusher`` approximates the paper's UR5 gripper by a vertical capsule finger: a dynamic body
held by a stiff, force-limited 6-DoF drive (a kinematic body pressed into clutter squeezes objects
out at metres per second; a force-limited drive yields instead: measured in the SAPIEN notes).
A push: appear just above the start point, press down to just below the surface there (never below
the floor), travel horizontally at constant speed, then leave (the finger is removed at once: a slow
lift only costs simulation time). The path is clipped so the finger stays
inside the bin walls. It has no visual: the top camera never sees it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import sapien

from mqa_rl.sim.geometry import BinSpec
from mqa_rl.sim.scene import CONTACT_OFFSET, TIMESTEP, BinWorld

PARK = np.array([0.9, 0.9, 0.6])        # out of the camera's view and away from the bin


@dataclass(frozen=True)
class PushResult:
    start: np.ndarray       # [3] executed start of the horizontal stroke (world)
    end: np.ndarray         # [3] executed end (where the drive target stopped)
    steps: int              # physics steps spent on the stroke (approach, press, travel, lift)
    reachable: bool = True          # the whole push was reachable (an arm may fail to reach; the finger never does)
    arm_collision: bool = False     # a robot part other than the pushing tool touched something
    tip_error_mean: float = 0.0     # tool tip's distance to the commanded push line during the stroke (m)
    tip_error_max: float = 0.0


class Pusher(Protocol):
    def attach(self, world: BinWorld) -> None: ...

    def push(self, world: BinWorld, start: np.ndarray, direction: np.ndarray, length: float) -> PushResult: ...


def clip_stroke(bin_spec: BinSpec, start: np.ndarray, direction: np.ndarray, length: float, clearance: float) -> tuple[np.ndarray, np.ndarray]:
    """A stroke's start and end in the xy-plane, kept ``clearance`` inside the walls (a tool's radius + margin)."""
    lim = bin_spec.half - clearance
    s = np.clip(np.asarray(start[:2], np.float64), -lim, lim)
    d = np.asarray(direction[:2], np.float64)
    t = length
    for k in range(2):
        if d[k] > 1e-9:
            t = min(t, (lim - s[k]) / d[k])
        elif d[k] < -1e-9:
            t = min(t, (-lim - s[k]) / d[k])
    return s, s + max(t, 0.0) * d


@dataclass
class FingerPusher:
    radius: float = 0.008          # m
    height: float = 0.10           # length of the finger's straight part (m)
    press: float = 0.015           # how far below the surface at the start point the finger aims (m)
    speed: float = 0.4             # horizontal travel speed (m/s)
    descend_speed: float = 0.5     # (m/s)
    clearance: float = 0.01        # the finger appears this far above the surface (m)
    stiffness: float = 2e3
    damping: float = 2e2
    force_limit: float = 40.0      # N
    wall_margin: float = 0.004     # clearance between finger and walls (m)

    def attach(self, world: BinWorld) -> None:
        entity = sapien.Entity()
        entity.name = "pusher"
        body = sapien.physx.PhysxRigidDynamicComponent()
        # capsule axis is x in PhysX: rotate it to stand vertically
        shape = sapien.physx.PhysxCollisionShapeCapsule(self.radius, self.height / 2, sapien.physx.PhysxMaterial(0.3, 0.3, 0.0))
        shape.local_pose = sapien.Pose(q=[0.7071068, 0, 0.7071068, 0])
        shape.set_density(2000)
        shape.contact_offset = CONTACT_OFFSET
        body.attach(shape)
        body.disable_gravity = True
        entity.add_component(body)
        entity.pose = sapien.Pose(PARK)
        world.scene.add_entity(entity)
        drive = world.scene.create_drive(None, sapien.Pose(), entity, sapien.Pose())
        for axis in ("x", "y", "z"):
            getattr(drive, f"set_drive_property_{axis}")(self.stiffness, self.damping, self.force_limit)
        drive.set_drive_property_slerp(self.stiffness, self.damping, self.force_limit)
        drive.set_drive_target(sapien.Pose(PARK))
        self._entity, self._body, self._drive = entity, body, drive
        self._world = world

    # ------------------------------------------------------------------------------------------
    def _teleport(self, p) -> None:
        self._entity.pose = sapien.Pose(np.asarray(p, np.float32))
        self._body.linear_velocity = np.zeros(3)
        self._body.angular_velocity = np.zeros(3)
        self._drive.set_drive_target(sapien.Pose(np.asarray(p, np.float32)))
        self._drive.set_drive_velocity_target(np.zeros(3), np.zeros(3))

    def _move(self, world: BinWorld, a: np.ndarray, b: np.ndarray, speed: float) -> int:
        """Drive the target from a to b at ``speed`` with velocity feed-forward; returns steps."""
        d = b - a
        dist = float(np.linalg.norm(d))
        n = max(int(np.ceil(dist / (speed * TIMESTEP))), 1)
        vel = d / (n * TIMESTEP)
        for k in range(1, n + 1):
            self._drive.set_drive_target(sapien.Pose(np.asarray(a + d * k / n, np.float32)))
            self._drive.set_drive_velocity_target(vel.astype(np.float32), np.zeros(3, np.float32))
            world.scene.step()
        self._drive.set_drive_velocity_target(np.zeros(3), np.zeros(3))
        return n

    def clip_to_bin(self, world: BinWorld, start: np.ndarray, direction: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
        """The stroke's start and end in the xy-plane, kept inside the walls by radius + margin."""
        return clip_stroke(world.bin, start, direction, length, self.radius + self.wall_margin)

    def push(self, world: BinWorld, start: np.ndarray, direction: np.ndarray, length: float) -> PushResult:
        s, e = self.clip_to_bin(world, start, direction, length)
        half = self.height / 2 + self.radius
        tip_z = max(float(start[2]) - self.press, self.radius + 0.001)       # finger tip height
        z = tip_z + half                                                       # body centre height
        above = np.array([s[0], s[1], max(float(start[2]), 0.0) + self.clearance + half])
        p0 = np.array([s[0], s[1], z])
        p1 = np.array([e[0], e[1], z])
        self._teleport(above)
        steps = self._move(world, above, p0, self.descend_speed)
        steps += self._move(world, p0, p1, self.speed)
        end = np.asarray(self._entity.pose.p, np.float64)
        self._teleport(PARK)
        return PushResult(np.array([s[0], s[1], tip_z]), np.array([end[0], end[1], tip_z]), steps)

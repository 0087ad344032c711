"""``ArmPusher``: the push primitive executed by a Franka Panda with a long stick (``mqa_rl.sim.panda``).

A push, as the tool tip's path (the stick held vertical):
  home (out of the camera's view) → over the start point at ``transit_height`` (above the walls)
  → fast down to ``clearance`` above the surface → slowly down to the press depth (the finger's
  start point) → along the push line (the finger's end point) → 1 cm back along it and slowly up
  by ``clearance`` (releasing what it pressed) → up to ``transit_height`` → home.
Every physics step's tip waypoint becomes joint targets by inverse kinematics (SAPIEN's bundled
pinocchio model, seeded with the previous solution), planned before anything moves, and the joints
follow by position drives with velocity feed-forward. A waypoint the arm cannot reach (IK failure,
joint limit, a jump between IK branches) is reported, never crashed on: an unreachable start means
no motion at all, an unreachable point on the line ends the stroke there. Contacts of any arm part
other than the stick (links, hand) with objects or the bin are reported too, as is how far the
tip strayed from the commanded line during the stroke.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sapien

from mqa_rl.sim import panda
from mqa_rl.sim.pusher import PushResult, clip_stroke
from mqa_rl.sim.scene import TIMESTEP, BinWorld

DOWN = np.diag([1.0, -1.0, -1.0])        # hand rotation with its z axis (the stick) pointing straight down
HOME_TIP = np.array([-0.45, -0.30, 0.50])  # out of the camera's view at any height, beside the pedestal
MAX_JOINT_STEP = 0.05                      # rad per physics step (12 rad/s): a larger jump is an IK branch flip


@dataclass
class ArmPlan:
    """Joint targets [T, 7] for the first ``reached`` of consecutive tip waypoints (IK reached them)."""

    qpos: np.ndarray
    reached: int


@dataclass
class PushPlan:
    """One push in joint targets (one row per physics step); ``approach`` is None when the start is out of reach."""

    start: np.ndarray                 # tip at the start of the stroke (world)
    line_end: np.ndarray              # commanded end of the stroke, cut where it became unreachable
    approach: np.ndarray | None       # home → over the start → down to the start
    stroke: np.ndarray | None         # along the push line
    back: np.ndarray | None           # up and home
    reachable: bool


@dataclass
class ArmPusher:
    speed: float = 0.4             # stroke speed along the push line (m/s, average; the finger's constant speed)
    press_speed: float = 0.25      # last part of the descent, from ``clearance`` above the surface (m/s)
    transit_speed: float = 1.0     # moves above the walls and fast descents (m/s, average; peak 1.9)
    press: float = 0.015           # how far below the surface at the start point the tip aims (m), as the finger
    clearance: float = 0.03        # the fast descent stops this far above the surface (m)
    transit_height: float = 0.50   # tip height for moves over the walls (wall top 0.45 m)
    release: float = 0.01          # back along the line before lifting (m): an object squeezed between the
                                   # stick and a wall would otherwise ride up with it and over the wall
    wall_margin: float = 0.004     # clearance between stick and walls (m)
    stiffness: float = 1e4         # joint position drives (N·m/rad)
    damping: float = 1e3
    tolerance: float = 0.005       # stated bound on the tip's distance to the push line (m), checked by tests
    contact_every: int = 8         # physics steps between contact checks (33 ms)
    _home: np.ndarray | None = field(default=None, init=False, repr=False)

    radius = panda.TOOL_RADIUS

    # ------------------------------------------------------------------------------------------ setup
    def attach(self, world: BinWorld) -> None:
        """Build the robot into ``world``'s (fresh) scene at the home configuration."""
        robot, pedestal = panda.build_panda(world.scene, render=world.camera is not None)
        self._robot = robot
        self._model = robot.create_pinocchio_model()
        names = [link.name for link in robot.links]
        self._hand_index = names.index(panda.HAND_LINK)
        self._hand = robot.links[self._hand_index]
        self._limits = np.array([j.limits[0] for j in robot.active_joints], np.float64)
        self._joints = robot.active_joints
        for j, effort in zip(self._joints, panda.JOINT_TORQUE_LIMITS):
            j.set_drive_properties(self.stiffness, self.damping, float(effort))
        home = self.home_qpos()
        robot.qpos = home.astype(np.float32)
        robot.qvel = np.zeros(len(home), np.float32)
        for j, q in zip(self._joints, home):
            j.set_drive_target(float(q))
            j.set_drive_velocity_target(0.0)
        self._links = list(robot.links)          # kept alive, so contacts hand back these very objects
        self._arm_body_ids = {id(link) for link in self._links}
        self._tool_shape = [s for s in self._hand.collision_shapes if isinstance(s, sapien.physx.PhysxCollisionShapeCapsule)][0]
        self._pedestal_body = pedestal.find_component_by_type(sapien.physx.PhysxRigidStaticComponent)
        self._world = world

    def home_qpos(self) -> np.ndarray:
        """Joint positions with the tip at ``HOME_TIP`` (computed once by IK from the Panda's ready pose)."""
        if self._home is None:
            ready = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
            q, ok = self._ik(HOME_TIP, ready, iterations=1000)
            if not ok:
                raise RuntimeError("the arm's home pose is unreachable: check panda.BASE_POSITION / HOME_TIP")
            self._home = q
        return self._home

    # ------------------------------------------------------------------------------------------ kinematics
    def _hand_pose_in_base(self, tip: np.ndarray) -> sapien.Pose:
        """Hand pose (base frame) that puts the vertical stick's tip at ``tip`` (world), the hand turned to
        face away from the base (a smooth function of the tip's position over the bin)."""
        d = tip[:2] - panda.BASE_POSITION[:2]
        yaw = np.arctan2(d[1], d[0])
        c, s = np.cos(yaw), np.sin(yaw)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ DOWN
        t = np.eye(4)
        t[:3, :3] = rot
        t[:3, 3] = tip - panda.BASE_POSITION + np.array([0.0, 0.0, panda.TOOL_LENGTH])
        return sapien.Pose(t)

    def _ik(self, tip: np.ndarray, seed: np.ndarray, iterations: int = 100) -> tuple[np.ndarray, bool]:
        q, ok, _ = self._model.compute_inverse_kinematics(self._hand_index, self._hand_pose_in_base(tip),
                                                          initial_qpos=seed, max_iterations=iterations)
        q = np.asarray(q, np.float64)
        ok = bool(ok) and bool(np.all(q >= self._limits[:, 0]) and np.all(q <= self._limits[:, 1]))
        return q, ok

    def plan(self, tips: np.ndarray, seed: np.ndarray) -> ArmPlan:
        """IK along tip waypoints [T, 3]; stops at the first one it cannot reach smoothly."""
        out, q = [], seed
        for tip in tips:
            nq, ok = self._ik(tip, q)
            if not ok or np.abs(nq - q).max() > MAX_JOINT_STEP * 4:
                break
            out.append(nq)
            q = nq
        return ArmPlan(np.array(out).reshape(-1, len(seed)), len(out))

    def tip_position(self) -> np.ndarray:
        """World position of the stick's tip, from the simulated hand link."""
        pose = self._hand.entity_pose
        return np.asarray(pose.p, np.float64) + pose.to_transformation_matrix()[:3, :3] @ np.array([0, 0, panda.TOOL_LENGTH])

    # ------------------------------------------------------------------------------------------ motion
    @staticmethod
    def _line(a: np.ndarray, b: np.ndarray, speed: float) -> np.ndarray:
        """Waypoints from a (excluded) to b (included), one per physics step, at rest at both ends with
        ``speed`` on average (a quintic time scaling: the wrist's 12 N·m cannot stop a 0.5 m stick
        moving at full speed within one step; an abrupt stop swings the tip by centimetres)."""
        n = max(int(np.ceil(np.linalg.norm(b - a) / (speed * TIMESTEP))), 1)
        t = np.arange(1, n + 1) / n
        s = t ** 3 * (10 - 15 * t + 6 * t ** 2)
        return a + (b - a) * s[:, None]

    def _follow(self, qpos: np.ndarray, q_from: np.ndarray, on_step=None) -> bool:
        """Drive the joints through ``qpos`` [T, 7], one row per physics step; returns whether an arm part
        other than the stick touched anything."""
        hit = False
        prev = q_from
        for k, q in enumerate(qpos):
            vel = (q - prev) / TIMESTEP
            for j, qi, vi in zip(self._joints, q, vel):
                j.set_drive_target(float(qi))
                j.set_drive_velocity_target(float(vi))
            self._world.scene.step()
            if on_step is not None:
                on_step(k)
            if k % self.contact_every == 0 and not hit:
                hit = self._arm_collides()
            prev = q
        for j in self._joints:
            j.set_drive_velocity_target(0.0)
        return hit

    def _arm_collides(self) -> bool:
        """Whether a link or the hand (not the stick) touches an object, the bin or the floor now. Bodies
        are matched by identity (SAPIEN hands back the same Python object for a live component): this
        runs every few physics steps over every contact of a 50-object pile."""
        arm, tool, pedestal = self._arm_body_ids, self._tool_shape, self._pedestal_body
        for contact in self._world.scene.get_contacts():
            b0, b1 = contact.bodies
            in0, in1 = id(b0) in arm, id(b1) in arm
            if in0 == in1:                     # no robot part, or the robot with itself
                continue
            shape, other = (contact.shapes[0], b1) if in0 else (contact.shapes[1], b0)
            if shape is tool or other is pedestal:
                continue
            if any(p.separation < 0 or np.any(np.asarray(p.impulse) != 0) for p in contact.points):
                return True
        return False

    def plan_push(self, bin_spec, start: np.ndarray, direction: np.ndarray, length: float) -> PushPlan:
        """Joint targets for one push (no physics): approach, stroke (cut where it becomes unreachable),
        retreat home. ``plan.reachable`` is False when any of it is out of reach."""
        s, e = clip_stroke(bin_spec, start, direction, length, self.radius + self.wall_margin)
        tip_z = max(float(start[2]) - self.press, self.radius + 0.001)
        surface = max(float(start[2]), 0.0)
        high_s = np.array([s[0], s[1], self.transit_height])
        near_s = np.array([s[0], s[1], min(surface + self.clearance, self.transit_height)])
        p0, p1 = np.array([s[0], s[1], tip_z]), np.array([e[0], e[1], tip_z])
        home, home_tip = self.home_qpos(), HOME_TIP.astype(np.float64)
        approach_tips = np.concatenate([self._line(home_tip, high_s, self.transit_speed),
                                        self._line(high_s, near_s, self.transit_speed),
                                        self._line(near_s, p0, self.press_speed)])
        approach = self.plan(approach_tips, home)
        if approach.reached < len(approach_tips):
            return PushPlan(p0, p0, None, None, None, reachable=False)
        stroke_tips = self._line(p0, p1, self.speed)
        stroke = self.plan(stroke_tips, approach.qpos[-1])
        last_q = stroke.qpos[-1] if stroke.reached else approach.qpos[-1]
        line_end = stroke_tips[stroke.reached - 1] if stroke.reached else p0
        release = line_end - self.release * _unit(line_end - p0)          # off the pushed objects first
        released = np.array([release[0], release[1], min(release[2] + self.clearance, self.transit_height)])
        high_e = np.array([release[0], release[1], self.transit_height])
        back_tips = np.concatenate([self._line(line_end, release, self.press_speed),
                                    self._line(release, released, self.press_speed),
                                    self._line(released, high_e, self.transit_speed),
                                    self._line(high_e, home_tip, self.transit_speed)])
        back = self.plan(back_tips, last_q)
        back_q = back.qpos if back.reached == len(back_tips) else \
            np.concatenate([back.qpos, self._joint_line(back.qpos[-1] if back.reached else last_q, home)])
        return PushPlan(p0, line_end, approach.qpos, stroke.qpos, back_q,
                        reachable=stroke.reached == len(stroke_tips) and back.reached == len(back_tips))

    def push(self, world: BinWorld, start: np.ndarray, direction: np.ndarray, length: float) -> PushResult:
        plan = self.plan_push(world.bin, start, direction, length)
        if plan.approach is None:                           # the start is out of reach: no motion at all
            return PushResult(plan.start.copy(), plan.start.copy(), 0, reachable=False)
        errors = []

        def track(k):
            errors.append(_distance_to_segment(self.tip_position(), plan.start, plan.line_end))

        hit = self._follow(plan.approach, self.home_qpos())
        hit |= self._follow(plan.stroke, plan.approach[-1], on_step=track)
        end = self.tip_position()
        last_q = plan.stroke[-1] if len(plan.stroke) else plan.approach[-1]
        hit |= self._follow(plan.back, last_q)
        err = np.array(errors) if errors else np.zeros(1)
        steps = len(plan.approach) + len(plan.stroke) + len(plan.back)
        return PushResult(plan.start.copy(), np.array([end[0], end[1], plan.start[2]]), steps,
                          reachable=plan.reachable, arm_collision=bool(hit),
                          tip_error_mean=float(err.mean()), tip_error_max=float(err.max()))

    def _joint_line(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Joint-space interpolation, the fallback retreat when the Cartesian one is not reachable."""
        n = max(int(np.ceil(np.abs(b - a).max() / MAX_JOINT_STEP)), 1)
        return a + (b - a) * (np.arange(1, n + 1) / n)[:, None]


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.zeros_like(v)


def _distance_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    denom = float(ab @ ab)
    t = 0.0 if denom < 1e-12 else float(np.clip((p - a) @ ab / denom, 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))

"""Build the MQA bin world in SAPIEN 3: ground, bin walls, objects, and (optionally) the camera.

Scenes are always *rebuilt* from stored poses rather than restored in place: PhysX keeps contact
and warm-start caches across ``unpack``, so an in-place restore does not replay the same physics,
while a fresh build at the same poses is bit-identical (measured; see docs/platform.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sapien

from mqa_rl.sim.assets import ObjectAsset
from mqa_rl.sim.geometry import BinSpec, CameraSpec

# One physics configuration for settling the dataset and for the env, so stored rest states stay
# at rest. Measured on hard scenes (benchmarks/env_step.py): PhysX's default 1 cm contact offset
# and 10 solver iterations cost 2.5x the time for no visible gain in this clutter.
TIMESTEP = 1 / 240            # physics step (s)
CONTACT_OFFSET = 0.002        # m
SOLVER_POSITION_ITERATIONS = 4
SOLVER_VELOCITY_ITERATIONS = 1
FLOOR_COLOR = (0.55, 0.55, 0.55, 1.0)
WALL_COLOR = (0.35, 0.40, 0.45, 1.0)
OBJECT_MATERIAL = (0.6, 0.5, 0.0)   # static friction, dynamic friction, restitution
MAX_DEPENETRATION_VELOCITY = 0.3    # m/s: objects pushed into each other separate gently

_keep_alive: list = []


def _keep_shaders_alive() -> None:
    """Hold one tiny camera for the whole process: without a live camera every new scene recompiles
    SAPIEN's shaders (~4 s each on lavapipe); with it a new scene with a camera costs ~0.1 s."""
    if not _keep_alive:
        scene = sapien.Scene()
        cam = scene.add_camera("keep_alive", 8, 8, 1.0, 0.1, 1.0)
        scene.update_render()
        cam.take_picture()
        _keep_alive.extend([scene, cam])


def _visual(vertices: np.ndarray, faces: np.ndarray, rgba) -> sapien.render.RenderShapeTriangleMesh:
    """A flat-shaded render mesh (vertices unshared so every face keeps its own normal)."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]          # [F, 3, 3]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    v = tri.reshape(-1, 3).astype(np.float32)
    f = np.arange(len(v), dtype=np.uint32).reshape(-1, 3)
    n = np.repeat(normals, 3, axis=0).astype(np.float32)
    uv = np.zeros((len(v), 2), dtype=np.float32)
    return sapien.render.RenderShapeTriangleMesh(v, f, n, uv, sapien.render.RenderMaterial(base_color=list(rgba)))


@dataclass
class BinWorld:
    """One SAPIEN scene holding the bin and its objects. ``objects[i]`` is the entity of ``assets[i]``."""

    scene: sapien.Scene
    assets: list[ObjectAsset]
    objects: list[sapien.Entity]
    bodies: list[sapien.physx.PhysxRigidDynamicComponent]
    camera: sapien.render.RenderCameraComponent | None
    bin: BinSpec
    # a second camera at the same pose and field of view, rendering finer (``build_world(answer_camera=...)``)
    answer_camera: sapien.render.RenderCameraComponent | None = None

    # ----------------------------------------------------------------------------- state
    def poses(self) -> np.ndarray:
        """[N, 7] float64 (x, y, z, qw, qx, qy, qz) of every object."""
        return np.array([np.concatenate([e.pose.p, e.pose.q]) for e in self.objects], dtype=np.float64)

    def speeds(self) -> np.ndarray:
        """[N] linear speed of every object (m/s)."""
        return np.array([np.linalg.norm(b.linear_velocity) for b in self.bodies])

    def all_asleep(self) -> bool:
        return all(b.is_sleeping for b in self.bodies)

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.scene.step()

    def settle(self, max_steps: int, check_every: int = 24, speed_tol: float | None = None) -> int:
        """Step until every object rests or ``max_steps``; returns steps run.

        Resting is PhysX's sleep test, or, with ``speed_tol`` (m/s), every object's linear speed and
        angular speed × 0.05 m below it (PhysX waits 0.4 s of stillness before sleeping a body)."""
        steps = 0
        while steps < max_steps:
            self.step(check_every)
            steps += check_every
            if self.all_asleep() or (speed_tol is not None and self.max_speed() < speed_tol):
                break
        return steps

    def max_speed(self) -> float:
        """Largest linear speed, or angular speed times 5 cm (a point on a typical object's rim)."""
        best = 0.0
        for b in self.bodies:
            if not b.is_sleeping:
                best = max(best, float(np.linalg.norm(b.linear_velocity)), 0.05 * float(np.linalg.norm(b.angular_velocity)))
        return best

    def entity_ids(self) -> np.ndarray:
        """[N] per-scene entity ids, the values of segmentation channel 1 for each object."""
        return np.array([e.per_scene_id for e in self.objects], dtype=np.int64)

    # ----------------------------------------------------------------------------- camera
    def render(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rgb uint8 [H, W, 3], depth float32 [H, W] metres along the view axis, entity ids int32 [H, W])."""
        if self.camera is None:
            raise RuntimeError("this BinWorld was built without a camera (build_world(..., camera=...))")
        self.scene.update_render()
        self.camera.take_picture()
        rgb = _rgb(self.camera)
        pos = self.camera.get_picture("Position")
        depth = np.where(pos[..., 3] < 1, -pos[..., 2], 0.0).astype(np.float32)
        seg = self.camera.get_picture("Segmentation")[..., 1].astype(np.int32)
        return rgb, depth, seg

    def render_answer(self) -> np.ndarray:
        """rgb uint8 [S, S, 3] of the answer camera (the same view as ``render``'s, finer)."""
        if self.answer_camera is None:
            raise RuntimeError("this BinWorld was built without an answer camera (build_world(..., answer_camera=...))")
        self.scene.update_render()
        self.answer_camera.take_picture()
        return _rgb(self.answer_camera)


def _rgb(camera: sapien.render.RenderCameraComponent) -> np.ndarray:
    return np.clip(camera.get_picture("Color")[..., :3] * 255 + 0.5, 0, 255).astype(np.uint8)


def _add_camera(scene: sapien.Scene, name: str, camera: CameraSpec) -> sapien.render.RenderCameraComponent:
    cam = scene.add_camera(name, camera.width, camera.height, np.deg2rad(camera.fovy_deg), camera.near, camera.far)
    cam.entity.pose = sapien.Pose(camera.position.astype(np.float32), camera.sapien_quaternion.astype(np.float32))
    return cam


def _static_box(scene: sapien.Scene, half_size, position, rgba, render: bool, kinematic: bool = False) -> sapien.Entity:
    """A box that does not fall: static (bin walls, floor), or kinematic when it must move (the sleeve)."""
    entity = sapien.Entity()
    if kinematic:
        body = sapien.physx.PhysxRigidDynamicComponent()
        body.kinematic = True
    else:
        body = sapien.physx.PhysxRigidStaticComponent()
    shape = sapien.physx.PhysxCollisionShapeBox(np.asarray(half_size, np.float32), sapien.physx.PhysxMaterial(*OBJECT_MATERIAL))
    shape.contact_offset = CONTACT_OFFSET
    body.attach(shape)
    entity.add_component(body)
    if render:
        rb = sapien.render.RenderBodyComponent()
        rb.attach(sapien.render.RenderShapeBox(np.asarray(half_size, np.float32), sapien.render.RenderMaterial(base_color=list(rgba))))
        entity.add_component(rb)
    entity.pose = sapien.Pose(np.asarray(position, np.float32))
    scene.add_entity(entity)
    return entity


def _object_entity(asset: ObjectAsset, pose: np.ndarray, render: bool) -> tuple[sapien.Entity, sapien.physx.PhysxRigidDynamicComponent]:
    entity = sapien.Entity()
    entity.name = asset.name
    body = sapien.physx.PhysxRigidDynamicComponent()
    material = sapien.physx.PhysxMaterial(*OBJECT_MATERIAL)
    for verts in asset.collision_parts:
        shape = sapien.physx.PhysxCollisionShapeConvexMesh(np.asarray(verts, np.float32), np.ones(3, np.float32), material)
        shape.set_density(asset.density)
        shape.contact_offset = CONTACT_OFFSET
        body.attach(shape)
    body.max_depenetration_velocity = MAX_DEPENETRATION_VELOCITY
    body.solver_position_iterations = SOLVER_POSITION_ITERATIONS
    body.solver_velocity_iterations = SOLVER_VELOCITY_ITERATIONS
    entity.add_component(body)
    if render:
        rb = sapien.render.RenderBodyComponent()
        for v in asset.visuals:
            rb.attach(_visual(v.vertices, v.faces, v.color))
        entity.add_component(rb)
    entity.pose = sapien.Pose(np.asarray(pose[:3], np.float32), np.asarray(pose[3:7], np.float32))
    return entity, body


def build_world(
    assets: list[ObjectAsset],
    poses: np.ndarray,
    *,
    bin_spec: BinSpec = BinSpec(),
    camera: CameraSpec | None = None,
    answer_camera: CameraSpec | None = None,
    asleep: bool = True,
) -> BinWorld:
    """A fresh scene with ``assets`` at ``poses`` [N, 7]. With ``camera`` it renders (needs Vulkan);
    without, it is physics only. ``answer_camera``: a second camera (``BinWorld.render_answer``), e.g. the
    same view at a finer resolution. ``asleep`` puts the objects to sleep (settled scenes stay still)."""
    if answer_camera is not None and camera is None:
        raise ValueError("answer_camera needs camera: a physics-only world renders nothing")
    render = camera is not None
    if render:
        _keep_shaders_alive()
        scene = sapien.Scene()
        scene.set_ambient_light([0.45, 0.45, 0.45])
        scene.add_directional_light([0.3, 0.2, -1.0], [0.7, 0.7, 0.7])
    else:
        scene = sapien.Scene([sapien.physx.PhysxCpuSystem()])
    scene.set_timestep(TIMESTEP)

    _static_box(scene, [1.0, 1.0, 0.05], [0, 0, -0.05], FLOOR_COLOR, render)   # floor top at z = 0
    _square_walls(scene, (0.0, 0.0), bin_spec.inner_size, bin_spec.wall_height, bin_spec.wall_thickness, render)

    cam = _add_camera(scene, "top", camera) if render else None
    answer = _add_camera(scene, "answer", answer_camera) if answer_camera is not None else None
    world = BinWorld(scene, [], [], [], cam, bin_spec, answer)
    for asset, pose in zip(assets, np.asarray(poses, dtype=np.float64)):
        add_object(world, asset, pose)
    if asleep:
        for b in world.bodies:
            b.put_to_sleep()
    return world


def _square_walls(scene: sapien.Scene, centre, inner_size: float, height: float, thickness: float, render: bool,
                  kinematic: bool = False) -> list[sapien.Entity]:
    """Four walls standing on the floor around ``centre`` (xy), ``inner_size`` apart inside."""
    cx, cy = float(centre[0]), float(centre[1])
    h, t = inner_size / 2, thickness
    walls = []
    for sx, sy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        half = [t / 2, h + t, height / 2] if sx else [h + t, t / 2, height / 2]
        pos = [cx + sx * (h + t / 2), cy + sy * (h + t / 2), height / 2]
        walls.append(_static_box(scene, half, pos, WALL_COLOR, render, kinematic))
    return walls


def add_sleeve(world: BinWorld, centre, inner_size: float, height: float, thickness: float = 0.01) -> list[sapien.Entity]:
    """Four temporary kinematic walls around ``centre`` (xy): a square tube of ``inner_size`` standing
    on the floor, into which scene generation pours objects before lifting it (``lift_sleeve``)."""
    return _square_walls(world.scene, centre, inner_size, height, thickness, world.camera is not None, kinematic=True)


def lift_sleeve(world: BinWorld, walls: list[sapien.Entity], speed: float, height: float) -> int:
    """Raise the sleeve at ``speed`` (m/s) by ``height`` so the poured column slumps gradually into a
    pile (as when a box is lifted off its contents), then remove it. Returns the physics steps."""
    for b in world.bodies:
        b.wake_up()
    starts = [np.asarray(w.pose.p, np.float64) for w in walls]
    n = max(int(np.ceil(height / (speed * TIMESTEP))), 1)
    for k in range(1, n + 1):
        for w, p in zip(walls, starts):
            w.find_component_by_type(sapien.physx.PhysxRigidDynamicComponent).kinematic_target = \
                sapien.Pose(np.asarray(p + [0, 0, height * k / n], np.float32))
        world.scene.step()
    for w in walls:
        world.scene.remove_entity(w)
    return n


def add_object(world: BinWorld, asset: ObjectAsset, pose: np.ndarray) -> sapien.Entity:
    """Add one object to a built world (rendered when the world has a camera)."""
    entity, body = _object_entity(asset, pose, render=world.camera is not None)
    world.scene.add_entity(entity)
    world.assets.append(asset)
    world.objects.append(entity)
    world.bodies.append(body)
    return entity

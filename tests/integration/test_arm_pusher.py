"""The arm pusher (a Panda with a stick) on real SAPIEN scenes: loading, a push that moves an
object with the tip on the line, out of the image when rendered, bit-identical replays, reporting,
and the error without the optional package."""

import importlib.util
import sys

import numpy as np
import pytest
import torch

from mqa_rl import keys
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.sim import arm_pusher, panda
from mqa_rl.sim.arm_pusher import ArmPusher
from mqa_rl.sim.pushers import make_pusher
from mqa_rl.sim.scene import build_world

needs_arm = pytest.mark.skipif(importlib.util.find_spec("mani_skill") is None,
                               reason="the arm needs the optional robot assets: pip install 'mqa_rl[arm]'")


@pytest.fixture(scope="module")
def arm_env(sparse_dataset):
    return SapienBinEnv(sparse_dataset, split=None, seed=0, max_pushes=3, pusher="arm")


def _robot_pixels(env) -> int:
    seg = env.world.render()[2]
    ids = [link.entity.per_scene_id for link in env.pusher._robot.links]
    return int(np.isin(seg, ids).sum())


@needs_arm
def test_arm_loads_and_resets_at_home(arm_env):
    arm_env.reset()
    arm = arm_env.pusher
    assert isinstance(arm, ArmPusher) and len(arm._robot.active_joints) == 7
    np.testing.assert_allclose(arm._robot.qpos, arm.home_qpos(), atol=1e-6)
    np.testing.assert_allclose(arm.tip_position(), arm_pusher.HOME_TIP, atol=2e-3)
    base = arm._robot.links[0].entity_pose.p
    np.testing.assert_allclose(base, panda.BASE_POSITION, atol=1e-6)
    assert any(e.name == "pedestal" for e in arm_env.world.scene.get_entities())


@needs_arm
def test_push_beside_an_object_moves_it_with_the_tip_on_the_line(sparse_dataset):
    scene = sparse_dataset.scenes[0]
    assets = sparse_dataset.assets(scene)
    world = build_world(assets, scene.poses, bin_spec=sparse_dataset.bin)
    arm = ArmPusher()
    arm.attach(world)
    before = world.poses()
    i = int(np.argmin(np.linalg.norm(before[:, :2], axis=1)))          # the object nearest the centre
    target = before[i, :2]
    direction = -target / max(np.linalg.norm(target), 1e-9) if np.linalg.norm(target) > 0.02 else np.array([1.0, 0.0])
    direction = -direction                                               # push outwards, through the object
    start = np.array([*(target - 0.08 * direction), 0.0])               # on the floor, 8 cm before its centre
    result = arm.push(world, start, direction, 0.14)
    world.settle(480, check_every=8, speed_tol=0.005)
    moved = np.linalg.norm(world.poses()[i, :2] - before[i, :2])
    assert result.reachable and not result.arm_collision
    assert moved > 0.02, f"the object moved only {moved * 1e3:.1f} mm"
    assert result.tip_error_max < arm.tolerance, f"tip strayed {result.tip_error_max * 1e3:.1f} mm from the line"
    assert np.linalg.norm(result.end[:2] - (start[:2] + 0.14 * direction)) < 0.01
    np.testing.assert_allclose(arm.tip_position(), arm_pusher.HOME_TIP, atol=0.01)    # back home


@needs_arm
def test_arm_is_out_of_the_image_when_observed(arm_env):
    td = arm_env.reset()
    assert _robot_pixels(arm_env) == 0
    td[keys.ACTION] = torch.tensor(actions.encode(0, 14, 10))
    out = arm_env.step(td)["next"]
    assert not out[keys.PUSH_UNREACHABLE].item()
    assert _robot_pixels(arm_env) == 0
    # the check can see the arm: with the tip over the bin centre, its stick is in the image
    arm = arm_env.pusher
    plan = arm.plan(arm._line(arm_pusher.HOME_TIP, np.array([0.0, 0.0, 0.3]), 0.5), arm.home_qpos())
    arm._robot.qpos = plan.qpos[-1].astype(np.float32)
    assert _robot_pixels(arm_env) > 20


@needs_arm
def test_seeded_replays_with_the_arm_are_bit_identical(small_dataset, assert_bit_identical_replays):
    assert_bit_identical_replays(lambda: SapienBinEnv(small_dataset, split=None, difficulties=["hard"], seed=5, max_pushes=3,
                                                      pusher="arm"), pushes=2, seed=1)


@needs_arm
def test_unreachable_push_is_reported_without_motion(sparse_dataset):
    scene = sparse_dataset.scenes[0]
    world = build_world(sparse_dataset.assets(scene), scene.poses, bin_spec=sparse_dataset.bin)
    arm = ArmPusher(transit_height=1.6)              # over the walls at 1.6 m: beyond the Panda's reach
    arm.attach(world)
    before = world.poses()
    result = arm.push(world, np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0]), 0.14)
    assert not result.reachable and result.steps == 0
    np.testing.assert_array_equal(world.poses(), before)
    np.testing.assert_allclose(arm._robot.qpos, arm.home_qpos(), atol=1e-6)


def test_finger_reports_the_execution_keys_as_zero(sparse_dataset):
    env = SapienBinEnv(sparse_dataset, split=None, seed=0, max_pushes=3)
    td = env.reset()
    for key in (keys.PUSH_UNREACHABLE, keys.ARM_COLLISION, keys.TIP_ERROR):
        assert key in env.observation_spec.keys(True, True)
        assert not td[key].any()
    td[keys.ACTION] = torch.tensor(actions.encode(0, 14, 10))
    out = env.step(td)["next"]
    assert not out[keys.PUSH_UNREACHABLE].any() and not out[keys.ARM_COLLISION].any() and not out[keys.TIP_ERROR].any()


def test_missing_package_gives_install_hint(monkeypatch, sparse_dataset):
    monkeypatch.setitem(sys.modules, "mani_skill", None)          # what an uninstalled package looks like
    with pytest.raises(panda.ArmAssetsMissing, match=r"pip install 'mqa_rl\[arm\]'"):
        make_pusher("arm")
    with pytest.raises(ImportError, match=r"pip install 'mqa_rl\[arm\]'"):
        SapienBinEnv(sparse_dataset, split=None, pusher="arm")
    with pytest.raises(ValueError, match="finger"):
        make_pusher("gripper")


@needs_arm
def test_contact_of_the_hand_is_reported(sparse_dataset):
    import sapien

    scene = sparse_dataset.scenes[0]
    world = build_world(sparse_dataset.assets(scene), scene.poses, bin_spec=sparse_dataset.bin)
    arm = ArmPusher()
    arm.attach(world)
    # a fixed block in the hand's way on its path from home to over the bin centre (the stick passes below it)
    block = sapien.Entity()
    body = sapien.physx.PhysxRigidStaticComponent()
    body.attach(sapien.physx.PhysxCollisionShapeBox([0.04, 0.04, 0.04], sapien.physx.PhysxMaterial(0.5, 0.5, 0.0)))
    block.add_component(body)
    block.pose = sapien.Pose([-0.225, -0.15, 1.05])
    world.scene.add_entity(block)
    result = arm.push(world, np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0]), 0.14)
    assert result.arm_collision

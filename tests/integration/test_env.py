"""SapienBinEnv on real SAPIEN scenes: specs, determinism, push physics, measurements, bad input."""

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from mqa_rl import keys
from mqa_rl.data import DatasetError
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv


@pytest.fixture(scope="module")
def env(small_dataset):
    return SapienBinEnv(small_dataset, split=None, seed=0, max_pushes=3)


def _easy_question(ds):
    scene = next(s for s in ds.scenes if s.difficulty == "easy")
    return f"{scene.id}/counting/{ds.classes[0]}"


def _step(env, td, action):
    td = td.clone()
    td[keys.ACTION] = torch.tensor(action)
    return env.step(td)


def test_specs(env):
    check_env_specs(env, seed=0)
    assert env.action_spec.space.n == 6273 == actions.NUM_ACTIONS


def test_seeded_determinism_bit_for_bit(small_dataset, assert_bit_identical_replays):
    assert_bit_identical_replays(lambda: SapienBinEnv(small_dataset, split=None, seed=7, max_pushes=3), pushes=3, seed=3)


def test_reset_to_same_question_gives_identical_frames(env, small_dataset):
    qid = _easy_question(small_dataset)
    a = env.reset(question_id=qid)
    _step(env, a, actions.encode(0, 14, 14))          # disturb the scene in between
    b = env.reset(question_id=qid)
    assert env.question.id == qid
    assert torch.equal(a[keys.RGB], b[keys.RGB]) and torch.equal(a[keys.DEPTH], b[keys.DEPTH])
    idx = small_dataset.questions.index(small_dataset.question(qid))
    c = env.reset(env.reset().empty().set(keys.RESET_QUESTION, torch.tensor([idx])))
    assert torch.equal(a[keys.RGB], c[keys.RGB])


def _clear_floor(env, depth, margin_px):
    """Pixels that see the bin floor with no object within ``margin_px`` (visible floor at a pixel
    means no object stands there: an object's lower part projects inside its own silhouette)."""
    floor = (depth > env.camera.distance - 0.003) & (np.abs(np.indices(depth.shape) - depth.shape[0] / 2).max(0) < 85)
    for _ in range(margin_px):
        floor[1:] &= floor[:-1]
        floor[:-1] &= floor[1:]
        floor[:, 1:] &= floor[:, :-1]
        floor[:, :-1] &= floor[:, 1:]
    return floor


def _floor_corridor(env):
    """Every push as (action, image path u, v) of its stroke at floor level."""
    h = env.camera.height
    length_px = env.push_length * env.camera.fy / env.camera.distance
    for d in range(8):
        dx, dy = actions.direction_xy(d)
        for row in range(4, 24):
            for col in range(4, 24):
                u, v = actions.cell_centre_uv(row, col, h, h)
                ts = np.linspace(0, length_px, 60)
                us, vs = u + dx * ts, v - dy * ts                 # image v runs along world −y
                if us.min() < 0 or vs.min() < 0 or us.max() >= h or vs.max() >= h:
                    continue
                yield actions.encode(d, row, col), us, vs


def test_push_into_empty_space_moves_nothing(sparse_dataset):
    env = SapienBinEnv(sparse_dataset, split=None, seed=0)
    td = env.reset()
    free = _clear_floor(env, td[keys.DEPTH][0].numpy(), 5)
    action = next((a for a, us, vs in _floor_corridor(env) if free[vs.astype(int), us.astype(int)].all()), None)
    assert action is not None, "no free corridor in the sparse scene"
    before = td[keys.OBJECT_POS].clone()
    out = _step(env, td, action)["next"]
    moved = (out[keys.OBJECT_POS] - before).norm(dim=-1).max().item()
    assert moved < 1e-3, moved
    assert out[keys.PUSH_START][2] < 0.02                 # the finger ran along the floor


def test_push_next_to_an_object_moves_it(env, small_dataset):
    """A push starting on the free floor beside an object, aimed through its centre, moves it."""
    td = env.reset(question_id=_easy_question(small_dataset))
    depth = td[keys.DEPTH][0].numpy()
    free = _clear_floor(env, depth, 5)
    pos = env.world.poses()[:, :3]
    h = env.camera.height
    best = None
    for obj, asset in enumerate(env.world.assets):
        reach = float(np.linalg.norm(asset.dimensions[:2])) / 2
        for d in range(8):
            direction = actions.direction_xy(d)
            for row in range(28):
                for col in range(28):
                    uv = actions.cell_centre_uv(row, col, h, h)
                    if not free[int(uv[1]), int(uv[0])]:
                        continue
                    start = env.camera.unproject(uv, depth[int(uv[1]), int(uv[0])])[:2]
                    rel = pos[obj, :2] - start
                    along = float(rel @ direction)
                    across = abs(float(rel[0] * direction[1] - rel[1] * direction[0]))
                    if reach + 0.01 < along < env.push_length - 0.02 and across < 0.005:
                        best = (obj, actions.encode(d, row, col))
                        break
                if best:
                    break
            if best:
                break
        if best:
            break
    assert best is not None, "no push aimed at an object from free floor in this scene"
    obj, action = best
    before = td[keys.OBJECT_POS][obj].clone()
    out = _step(env, td, action)["next"]
    assert (out[keys.OBJECT_POS][obj] - before).norm().item() > 0.01


def test_measurements_agree_with_segmentation(env, small_dataset):
    scene = next(s for s in small_dataset.scenes if s.difficulty == "hard")
    td = env.reset(question_id=f"{scene.id}/counting/{small_dataset.classes[3]}")
    td = _step(env, td, actions.encode(2, 20, 10))["next"]
    _, _, seg = env.world.render()
    ids = env.world.entity_ids()
    n = len(scene.objects)
    info = td[keys.INFO]
    assert info["object_mask"].sum() == n and not info["object_mask"][n:].any()
    vis = info["visible_area"][:n].numpy()
    assert np.array_equal(vis, np.array([(seg == i).sum() for i in ids], dtype=np.float32))
    full = info["full_area"][:n].numpy()
    assert (vis <= full + 1).all()
    expect = np.where(full > 0, 1 - vis / np.maximum(full, 1), 1).clip(0, 1)
    np.testing.assert_allclose(info["overlap"][:n].numpy(), expect, rtol=1e-6)
    classes = [o.class_name for o in scene.objects]
    assert info["target_mask"][:n].tolist() == [c == small_dataset.classes[3] for c in classes]
    pos = env.world.poses()[:, :3]
    np.testing.assert_allclose(info["object_pos"][:n].numpy(), pos, rtol=0, atol=1e-6)
    assert small_dataset.answers[int(info["answer"])] == env.question.answer


def test_full_area_matches_isolated_render_after_a_push(env, small_dataset):
    import sapien

    td = env.reset(question_id=_easy_question(small_dataset))
    td = _step(env, td, actions.encode(1, 12, 12))["next"]
    full = td[keys.FULL_AREA].numpy()
    objs = env.world.objects
    comps = [o.find_component_by_type(sapien.render.RenderBodyComponent) for o in objs]
    for i in range(0, len(objs), 4):
        for j, c in enumerate(comps):
            c.visibility = float(i == j)
        _, _, seg = env.world.render()
        area = (seg == objs[i].per_scene_id).sum()
        assert abs(area - full[i]) <= max(3, 0.01 * area), (i, area, full[i])
    for c in comps:
        c.visibility = 1.0


def test_stop_terminates_and_keeps_the_scene(env):
    td = env.reset()
    out = _step(env, td, actions.STOP)["next"]
    assert out["terminated"].item() and out["done"].item() and not out["truncated"].item()
    assert out[keys.IS_STOP].item()
    assert torch.equal(out[keys.RGB], td[keys.RGB])


def test_truncation_after_max_pushes(env):
    td = env.reset()
    for k in range(3):
        out = _step(env, td, actions.encode(k, 14, 14))["next"]
        td = out
        assert out["truncated"].item() == (k == 2) and not out["terminated"].item()
    assert out[keys.PUSH_COUNT].item() == 3


@pytest.mark.parametrize("bad", [torch.tensor(6273), torch.tensor(-1), torch.tensor(3.0), torch.tensor(float("nan")), torch.tensor([1, 2])])
def test_bad_actions_raise_and_env_stays_usable(env, bad):
    td = env.reset()
    td[keys.ACTION] = bad
    with pytest.raises(ValueError, match="action"):
        env._step(td)
    assert not _step(env, td, actions.STOP)["next", "truncated"].item()


def test_bad_construction_and_reset_arguments(small_dataset, sparse_dataset, tmp_path, env):
    with pytest.raises(ValueError, match="unknown question id"):
        env.reset(question_id="scene_999/counting/unicorn")
    env.reset()                                           # still usable
    with pytest.raises(DatasetError, match="does not exist"):
        SapienBinEnv(tmp_path / "missing")
    with pytest.raises(ValueError, match="allowed"):
        SapienBinEnv(small_dataset, question_types=["colour"])
    with pytest.raises(ValueError, match="no question"):
        SapienBinEnv(sparse_dataset, split="test")          # its single scene is in train
    with pytest.raises(ValueError, match="reset_question"):
        env.reset(env.reset().empty().set(keys.RESET_QUESTION, torch.tensor([10**9])))


def test_episode_video_mp4_and_gif(env, tmp_path):
    import cv2

    from mqa_rl.envs.video import episode_frames, write_video
    from mqa_rl.modules.push.random_policy import RandomMQAPolicy

    r = env.rollout(4, RandomMQAPolicy(3, seed=2))
    frames = episode_frames(r, env.camera, env.question.text)
    assert len(frames) == r.shape[0] + 1
    for suffix in ("mp4", "gif"):
        path = write_video(frames, tmp_path / f"ep.{suffix}")
        cap = cv2.VideoCapture(str(path))
        assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == len(frames)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ep.gif", "ep.mp4"]       # no temp files left
    with pytest.raises(ValueError, match="mp4 or .gif"):
        write_video(frames, tmp_path / "ep.avi")
    # the arrow is drawn where the push went: the frame differs from the raw image
    if not r["next", keys.IS_STOP][0].item():
        raw = cv2.resize(r[keys.RGB][0].numpy().transpose(1, 2, 0), None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST)
        assert (frames[0][-raw.shape[0]:] != raw).any()

"""Piled scenes: real-size objects, occlusion that needs manipulation, the privileged reference."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from mqa_rl import keys
from mqa_rl.data import DatasetError, MQADataset
from mqa_rl.data.object_sizes import REAL_LENGTH
from mqa_rl.data.objects import make_object
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.modules.push.privileged_policy import PrivilegedPushPolicy


@pytest.mark.parametrize("class_name", sorted(REAL_LENGTH))
def test_objects_have_their_reference_size(class_name):
    for i, (length, reference) in enumerate(REAL_LENGTH[class_name]):
        assert reference
        assert make_object(class_name, i).dimensions.max() == pytest.approx(length, rel=1e-9)


def test_scenes_are_piles_inside_the_bin(small_dataset):
    b = small_dataset.bin
    for scene in small_dataset.scenes:
        poses = scene.poses
        assert b.inside(poses[:, :3]).all() and (poses[:, 2] < b.wall_height).all()
    hard = [s for s in small_dataset.scenes if s.difficulty == "hard"]
    # a pile, not a layer: hard scenes stack objects well above the tallest object's height (~0.1 m)
    assert max(s.poses[:, 2].max() for s in hard) > 0.15


@pytest.fixture(scope="module")
def hard_env(small_dataset):
    return SapienBinEnv(small_dataset, split=None, difficulties=["hard"], question_types=["counting"], seed=0)


def test_hard_piles_hide_most_of_some_targets_at_reset(hard_env):
    """The task's premise: on a hard pile some COUNTING targets are mostly hidden in the first image (χ > 0.8)."""
    for q in hard_env.questions:
        td = hard_env.reset(question_id=q.id)
        if bool((td[keys.OVERLAP][td[keys.TARGET_MASK]] > 0.8).any()):
            return
    pytest.fail("hard piles should hide some targets at reset")


def _hidden_questions(env, n):
    """Up to ``n`` hard COUNTING questions whose targets are mostly hidden at reset, with their mean χ."""
    out = []
    for q in env.questions:
        if q.answer == "0":
            continue
        td = env.reset(question_id=q.id)
        chi = td[keys.OVERLAP][td[keys.TARGET_MASK]].mean().item()
        if 0.3 < chi < 1.0:
            out.append((q, chi))
    return sorted(out, key=lambda x: -x[1])[:n]


@pytest.mark.slow
def test_privileged_policy_lowers_target_overlap_on_a_hard_scene(hard_env):
    questions = _hidden_questions(hard_env, 4)
    assert questions, "the small hard scenes should hide some targets"
    policy = PrivilegedPushPolicy(hard_env)
    drops = []
    for q, chi0 in questions:
        td = hard_env.reset(question_id=q.id)
        for _ in range(hard_env.max_pushes):
            td = policy(td)
            if int(td[keys.ACTION]) == actions.STOP:
                break
            td = hard_env.step(td)["next"]
        drops.append(chi0 - td[keys.OVERLAP][td[keys.TARGET_MASK]].mean().item())
    assert np.mean(drops) > 0.05 and max(drops) > 0.15, drops


def test_privileged_policy_stops_when_nothing_is_hidden(small_dataset):
    env = SapienBinEnv(small_dataset, split=None, question_types=["counting"], seed=0)
    q = next(q for q in env.questions if q.answer == "0")        # no target: nothing to reveal
    td = env.reset(question_id=q.id)
    assert int(PrivilegedPushPolicy(env)(td)[keys.ACTION]) == actions.STOP


def test_preview_leaves_the_episode_untouched(hard_env, small_dataset):
    q = hard_env.questions[0]
    td = hard_env.reset(question_id=q.id)
    before = hard_env.world.poses()
    action = actions.encode(0, 14, 10)
    preview = hard_env.preview(action)
    assert np.array_equal(hard_env.world.poses(), before)
    td[keys.ACTION] = torch.tensor(action)
    after = hard_env.step(td)["next"]
    assert preview["visible"].shape == after[keys.VISIBLE_AREA][after[keys.OBJECT_MASK]].shape


def test_an_old_schema_dataset_asks_to_regenerate(small_dataset_dir, tmp_path):
    import shutil

    old = tmp_path / "old"
    shutil.copytree(small_dataset_dir, old)
    manifest = json.loads((old / "manifest.json").read_text())
    manifest["schema_version"] = 1
    (old / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match="old dataset schema 1.*regenerate"):
        MQADataset(old)


def test_refined_teacher_keeps_the_direction_and_shows_the_targets_at_least_as_well(hard_env):
    q, _ = _hidden_questions(hard_env, 1)[0]
    hard_env.reset(question_id=q.id)
    plain = PrivilegedPushPolicy(hard_env, lookahead=1, order="visible_first", geometry="visible")
    refined = PrivilegedPushPolicy(hard_env, lookahead=1, order="visible_first", geometry="visible", refine_radius=1)
    a, b = plain.choose(), refined.choose()
    assert a != actions.STOP
    (da, ra, ca), (db, rb, cb) = actions.decode(a), actions.decode(b)
    assert da == db and abs(ra - rb) <= 1 and abs(ca - cb) <= 1
    target = hard_env.ground_truth()["target"]
    assert refined.score(hard_env.preview(b), target) >= refined.score(hard_env.preview(a), target)
    with pytest.raises(ValueError, match="refine_radius"):
        PrivilegedPushPolicy(hard_env, refine_radius=-1)

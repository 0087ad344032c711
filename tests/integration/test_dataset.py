"""The generated dataset: scenes settled in SAPIEN, splits, questions, determinism."""

import hashlib
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from mqa_rl.data import MQADataset, generate_dataset
from mqa_rl.data.questions import QUESTION_TYPES
from mqa_rl.sim.geometry import BinSpec

from conftest import SMALL


def _digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_api_shape(small_dataset):
    ds = small_dataset
    assert len(ds.classes) == 20 and len(set(ds.classes)) == 20
    assert len(ds.scenes) == sum(SMALL.values())
    counts = Counter(s.difficulty for s in ds.scenes)
    assert counts == Counter({k: v for k, v in SMALL.items() if v})
    for s in ds.scenes:
        assert len(s.objects) == {"easy": 20, "medium": 35, "hard": 50}[s.difficulty]
        names = [o.name for o in s.objects]
        assert len(set(names)) == len(names), "objects are drawn without repetition"
        assert s.split in ("train", "test")
    per_scene = Counter((q.scene_id, q.type) for q in ds.questions)
    for s in ds.scenes:
        assert [per_scene[(s.id, t)] for t in QUESTION_TYPES] == [20, 20, 380, 380]
    q = ds.question(ds.questions[0].id)
    assert q.type in QUESTION_TYPES and q.answer in ds.answers and q.classes[0] in ds.classes
    assert ds.vocab.decode(q.tokens) == " ".join(__import__("mqa_rl.data.vocab", fromlist=["words"]).words(q.text))
    with pytest.raises(KeyError, match="unknown question id"):
        ds.question("nope")
    with pytest.raises(ValueError, match="allowed"):
        ds.select(split="validation")


def test_oracle_counts_match_scene_contents(small_dataset):
    ds = small_dataset
    for s in ds.scenes:
        present = Counter(o.class_name for o in s.objects)
        for q in ds.select(types="counting"):
            if q.scene_id == s.id:
                assert int(q.answer) == present[q.classes[0]]


def test_settled_scenes_rest_inside_the_bin(small_dataset):
    bin_spec = small_dataset.bin
    for s in small_dataset.scenes:
        p = s.poses
        assert np.isfinite(p).all()
        assert bin_spec.inside(p[:, :3]).all()
        assert (p[:, 2] < bin_spec.wall_height).all()
        np.testing.assert_allclose(np.linalg.norm(p[:, 3:], axis=1), 1, atol=1e-5)


def test_settled_scene_stays_still_when_rebuilt(small_dataset):
    """Stored poses are a rest state: rebuilt and simulated for 1 s, nothing moves more than 2 mm."""
    from mqa_rl.sim.scene import build_world

    s = next(s for s in small_dataset.scenes if s.difficulty == "hard")
    world = build_world(small_dataset.assets(s), s.poses, asleep=False)
    world.step(240)
    moved = np.linalg.norm(world.poses()[:, :3] - s.poses[:, :3], axis=1)
    assert moved.max() < 0.002, moved.max()


def test_same_seed_same_bytes_in_one_process_or_two_other_seed_differs(small_dataset_dir, tmp_path):
    small = {"easy": 1, "hard": 1}
    a = generate_dataset(tmp_path / "a", seed=3, num_scenes=small).root
    b = generate_dataset(tmp_path / "b", seed=3, num_scenes=small, workers=2).root
    c = generate_dataset(tmp_path / "c", seed=4, num_scenes=small).root
    assert _digest(a) == _digest(b)
    assert (a / "scenes.json").read_bytes() != (c / "scenes.json").read_bytes()


def test_split_is_stratified_by_level(tmp_path):
    ds = generate_dataset(tmp_path / "d", seed=0, num_scenes={"easy": 10})
    assert Counter(s.split for s in ds.scenes) == Counter({"train": 7, "test": 3})


def test_bad_arguments_are_refused(tmp_path):
    with pytest.raises(ValueError, match="allowed"):
        generate_dataset(tmp_path / "x", num_scenes={"extreme": 1})
    assert not (tmp_path / "x").exists()


def test_asset_roundtrip_matches_library(small_dataset):
    from mqa_rl.data.objects import make_object
    from mqa_rl.sim.assets import ObjectAsset

    fresh = ObjectAsset.from_model(make_object(small_dataset.classes[0], 1))
    loaded = small_dataset.asset(small_dataset.classes[0], 1)
    assert len(fresh.collision_parts) == len(loaded.collision_parts)
    for a, b in zip(fresh.collision_parts, loaded.collision_parts):
        # stored parts are convex hulls of the same points: same vertex set
        assert {tuple(r) for r in np.round(b, 7)} <= {tuple(r) for r in np.round(a, 7)}
    assert loaded.mass == pytest.approx(fresh.mass, rel=1e-5)

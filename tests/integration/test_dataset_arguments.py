"""generate_dataset and MQADataset.select refuse bad arguments up front and leave nothing on disk."""

import itertools
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mqa_rl.data import MQADataset, generate_dataset

TINY = {"easy": 2, "medium": 2, "hard": 2}          # objects per scene: settling is quick


def _nothing_written(parent, name):
    return not [p for p in parent.iterdir() if p.name == name or p.name.startswith(f".{name}.")]


@pytest.mark.parametrize("plan", [{"easy": 0, "medium": 0, "hard": 0}, {}, {"easy": -1}])
def test_a_plan_without_scenes_is_refused_and_writes_nothing(tmp_path, plan):
    with pytest.raises(ValueError, match="num_scenes"):
        generate_dataset(tmp_path / "ds", num_scenes=plan)
    assert _nothing_written(tmp_path, "ds")
    generate_dataset(tmp_path / "ds", num_scenes={"easy": 1}, objects_per_scene=TINY)   # nothing blocks a re-run


@pytest.mark.parametrize("plan, named", [
    ({"easy": 1, "medium": -2}, "'medium'"), ({"easy": True}, "'easy'"), ({"easy": 1.0}, "'easy'"),
    ({"hard": "2"}, "'hard'"), ([("easy", 1)], "map difficulty"),
])
def test_bad_scene_counts_name_their_level(tmp_path, plan, named):
    with pytest.raises(ValueError, match=named):
        generate_dataset(tmp_path / "ds", num_scenes=plan)
    assert _nothing_written(tmp_path, "ds")


@pytest.mark.parametrize("kwargs, message", [
    ({"objects_per_scene": {"easy": 0}}, "objects_per_scene"), ({"seed": -1}, "seed"), ({"seed": 1.5}, "seed"),
    ({"train_fraction": float("nan")}, "train_fraction"), ({"train_fraction": 1}, "train_fraction"),
])
def test_other_bad_arguments(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        generate_dataset(tmp_path / "ds", num_scenes={"easy": 1}, **kwargs)
    assert _nothing_written(tmp_path, "ds")


def test_existing_folder_is_refused_before_any_work(small_dataset_dir):
    t0 = time.perf_counter()
    with pytest.raises(FileExistsError, match="overwrite=True"):
        generate_dataset(small_dataset_dir, num_scenes={"hard": 40})        # minutes of settling if it started
    assert time.perf_counter() - t0 < 5
    MQADataset(small_dataset_dir)


def test_overwrite_refuses_a_folder_that_is_not_a_dataset(tmp_path):
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "thesis.txt").write_text("precious")
    with pytest.raises(FileExistsError, match="not an mqa_rl dataset"):
        generate_dataset(tmp_path / "notes", num_scenes={"easy": 1}, overwrite=True)
    assert (tmp_path / "notes" / "thesis.txt").read_text() == "precious"
    (tmp_path / "afile").write_text("x")
    with pytest.raises(FileExistsError, match="is a file"):
        generate_dataset(tmp_path / "afile", num_scenes={"easy": 1}, overwrite=True)


@pytest.mark.parametrize("kwargs", [{"difficulties": ["extreme"]}, {"difficulties": ["Hard"]}, {"difficulties": "Easy"},
                                    {"split": ["train", "dev"]}, {"types": 3}, {"difficulties": 3}])
def test_select_refuses_unknown_names(small_dataset, kwargs):
    with pytest.raises(ValueError, match="allowed|a name or a list"):
        small_dataset.select(**kwargs)


def test_select_filters(small_dataset):
    hard = small_dataset.select(difficulties="hard")
    assert hard and all(small_dataset.scene(q.scene_id).difficulty == "hard" for q in hard)
    assert len(small_dataset.select(difficulties=["easy", "medium", "hard"])) == len(small_dataset.questions)


counts = st.one_of(st.integers(-2, 2), st.booleans(), st.floats(allow_nan=True), st.text(max_size=2), st.none())
RUNS = itertools.count()
plans = st.dictionaries(st.sampled_from(["easy", "medium", "hard", "Hard", "extreme"]), counts, max_size=3)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(plan=plans)
def test_any_scene_plan_loads_or_is_refused_with_nothing_on_disk(tmp_path, plan):
    name = f"ds{next(RUNS)}"
    try:
        ds = generate_dataset(tmp_path / name, num_scenes=plan, objects_per_scene=TINY)
    except ValueError as e:
        assert "num_scenes" in str(e) or "difficulty" in str(e)
        assert _nothing_written(tmp_path, name)
        return
    assert all(type(v) is int and v >= 0 for v in plan.values()) and sum(plan.values()) > 0
    assert len(MQADataset(tmp_path / name).scenes) == len(ds.scenes) == sum(plan.values())

"""Tests for the procedural household-object library."""

import os
import re
import subprocess
import sys

import numpy as np
import pytest

from conftest import REPO
from mqa_rl.data.objects import (
    CLASS_NAMES,
    CLASS_PHRASES,
    INSTANCES_PER_CLASS,
    ObjectModel,
    make_library,
    make_object,
)

MIN_DIMENSION, MAX_DIMENSION = 0.012, 0.30   # real sizes; the bin is 0.40 m wide


@pytest.fixture(scope="module")
def library() -> list[ObjectModel]:
    return make_library()


def test_library_has_twenty_classes_of_three_instances(library):
    assert INSTANCES_PER_CLASS == 3
    assert len(CLASS_NAMES) == 20 == len(set(CLASS_NAMES))
    assert {"can", "food_box", "book", "scissors", "gamepad"} <= set(CLASS_NAMES)
    assert all(re.fullmatch(r"[a-z]+(_[a-z]+)*", name) for name in CLASS_NAMES)
    assert len(library) == 60
    expected_order = [(c, i) for c in CLASS_NAMES for i in range(INSTANCES_PER_CLASS)]
    assert [(obj.class_name, obj.instance_id) for obj in library] == expected_order
    names = [obj.name for obj in library]
    assert len(set(names)) == len(names)
    assert names[0] == f"{CLASS_NAMES[0]}_0"


def test_parts_are_convex_watertight_meshes(library):
    for obj in library:
        assert 1 <= len(obj.parts) <= 15, obj.name
        for part in obj.parts:
            mesh = part.mesh
            assert mesh.is_watertight and mesh.is_convex, obj.name
            assert mesh.vertices.dtype == np.float64 and np.issubdtype(mesh.faces.dtype, np.integer)
            assert len(mesh.vertices) < 200, obj.name
            assert mesh.volume > 0, obj.name
            assert len(part.color) == 4 and all(0.0 <= c <= 1.0 for c in part.color), obj.name
    assert sum(len(obj.parts) for obj in library) <= 300


def test_dimensions_fit_the_bin(library):
    for obj in library:
        dims = obj.dimensions
        assert dims.shape == (3,)
        assert MIN_DIMENSION <= dims.min() and dims.max() <= MAX_DIMENSION, (obj.name, dims)
        assert dims.max() >= 0.04, (obj.name, dims)


def test_frame_is_centred_on_bounding_box(library):
    for obj in library:
        lower, upper = obj.bounds
        np.testing.assert_allclose(lower + upper, 0.0, atol=1e-9, err_msg=obj.name)
        np.testing.assert_allclose(upper - lower, obj.dimensions)


def test_physical_properties_are_plausible(library):
    for obj in library:
        assert 200.0 <= obj.density <= 1500.0, obj.name
        assert obj.volume == pytest.approx(sum(p.mesh.volume for p in obj.parts))
        assert obj.mass == pytest.approx(obj.density * obj.volume)
        assert 0.005 <= obj.mass <= 1.5, (obj.name, obj.mass)
    masses = {obj.name: obj.mass for obj in library}
    assert 0.1 <= masses["can_0"] <= 0.3
    assert 0.04 <= masses["tennis_ball_0"] <= 0.08


def test_library_is_deterministic(library):
    again = make_library()
    for first, second in zip(library, again):
        assert first.name == second.name and first.density == second.density
        assert len(first.parts) == len(second.parts)
        for a, b in zip(first.parts, second.parts):
            assert a.color == b.color
            assert a.mesh.vertices.tobytes() == b.mesh.vertices.tobytes()
            assert a.mesh.faces.tobytes() == b.mesh.faces.tobytes()


def test_instances_of_a_class_differ_in_size_and_colour(library):
    for class_name in CLASS_NAMES:
        instances = [obj for obj in library if obj.class_name == class_name]
        for i, a in enumerate(instances):
            for b in instances[i + 1 :]:
                assert not np.allclose(a.dimensions, b.dimensions, atol=1e-3), (a.name, b.name)
                assert {p.color for p in a.parts} != {p.color for p in b.parts}, (a.name, b.name)


def test_make_object_matches_library(library):
    obj = make_object("scissors", 2)
    assert obj.name == "scissors_2"
    assert np.array_equal(obj.dimensions, library[CLASS_NAMES.index("scissors") * 3 + 2].dimensions)
    assert make_object("can", np.int64(1)).instance_id == 1


def test_unknown_class_raises_helpful_error():
    with pytest.raises(ValueError, match="unknown object class 'teapot'") as info:
        make_object("teapot", 0)
    assert all(name in str(info.value) for name in CLASS_NAMES)


@pytest.mark.parametrize("bad_id", [-1, 3, 1.0, True])
def test_bad_instance_id_raises_helpful_error(bad_id):
    with pytest.raises(ValueError, match=r"instance_id .*\[0, 1, 2\]"):
        make_object("can", bad_id)


def test_phrases_cover_every_class_with_correct_article():
    assert set(CLASS_PHRASES) == set(CLASS_NAMES)
    for class_name, (singular, plural) in CLASS_PHRASES.items():
        article, noun = singular.split(" ", 1)
        assert article == ("an" if noun[0] in "aeiou" else "a"), singular
        assert plural == plural.lower() and "_" not in plural, plural
    assert CLASS_PHRASES["can"] == ("a can", "cans")
    assert CLASS_PHRASES["apple"] == ("an apple", "apples")
    assert CLASS_PHRASES["scissors"] == ("a pair of scissors", "scissors")
    assert CLASS_PHRASES["food_box"] == ("a food box", "food boxes")


def test_import_does_not_pull_in_simulators():
    """Dataset tooling must be able to use the library without sapien or torch."""
    code = "import sys, mqa_rl.data.objects; print(any(m in sys.modules for m in ('sapien', 'torch')))"
    repo_root = str(REPO)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [repo_root, os.environ.get("PYTHONPATH")]))}
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    assert result.stdout.strip() == "False"

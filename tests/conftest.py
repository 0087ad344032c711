"""Shared fixtures: one small real dataset (settled in SAPIEN) per test session."""

from __future__ import annotations

import pytest

SMALL = {"easy": 2, "medium": 1, "hard": 2}


@pytest.fixture(scope="session")
def small_dataset_dir(tmp_path_factory):
    from mqa_rl.data import generate_dataset

    out = tmp_path_factory.mktemp("mqa") / "small"
    generate_dataset(out, seed=0, num_scenes=SMALL)
    return out


@pytest.fixture(scope="session")
def small_dataset(small_dataset_dir):
    from mqa_rl.data import MQADataset

    return MQADataset(small_dataset_dir)


@pytest.fixture(scope="session")
def sparse_dataset(tmp_path_factory):
    """One easy scene of only 4 objects: free floor for pushes into empty space."""
    from mqa_rl.data import generate_dataset

    return generate_dataset(tmp_path_factory.mktemp("mqa") / "sparse", seed=0, num_scenes={"easy": 1},
                            objects_per_scene={"easy": 4})

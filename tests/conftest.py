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


@pytest.fixture(scope="session")
def assert_bit_identical_replays():
    """Check that two fresh envs from ``make_env()`` give bit-identical tensordicts over a reset and
    ``pushes`` random pushes drawn from ``seed``."""
    import torch

    from mqa_rl import keys
    from mqa_rl.envs import actions

    def run(make_env, pushes: int, seed: int):
        env = make_env()
        gen = torch.Generator().manual_seed(seed)
        td = env.reset()
        out = [td]
        for _ in range(pushes):
            td[keys.ACTION] = torch.randint(0, actions.NUM_PUSHES, (), generator=gen)
            td = env.step(td)["next"].clone()
            out.append(td)
        return out

    def check(make_env, pushes: int, seed: int) -> None:
        for x, y in zip(run(make_env, pushes, seed), run(make_env, pushes, seed)):
            for key in x.keys(True, True):
                assert torch.equal(x[key], y[key]), key

    return check

"""Shared fixtures: one small real dataset (settled in SAPIEN) per test session."""

from __future__ import annotations

from pathlib import Path

import pytest

from ray_cluster import ray_cluster  # noqa: F401  (the ray lane's two-node cluster fixture)

REPO = Path(__file__).resolve().parents[1]      # the checkout the tests run in

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


# ----------------------------------------------------------------------------------------- answering
def system_registry() -> dict:
    """The MQA systems of recipes/conf/systems.yaml (id -> entry), the registry every recipe composes."""
    from omegaconf import OmegaConf

    return OmegaConf.to_container(OmegaConf.load(REPO / "recipes" / "conf" / "systems.yaml"))["systems"]


def compose_recipe_config(name: str, overrides: list[str]):
    """A recipe's hydra config (recipes/conf/<name>.yaml) with overrides, as its command line would give."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(REPO / "recipes" / "conf"), version_base="1.3"):
        return compose(name, overrides=overrides)


def load_recipe(name: str):
    """recipes/<name>.py as a module (recipes/ is no package), to call its functions in-process."""
    import importlib.util

    recipes = REPO / "recipes"
    spec = importlib.util.spec_from_file_location(f"recipe_{name}", recipes / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def answering_root(small_dataset_dir, tmp_path_factory):
    """A tiny answering pipeline root: random and no-manipulation rollouts (train: 2 COUNTING questions
    per level, 2 rollouts each of the random policy; test: 2 per level) on the small dataset, at most
    2 pushes per episode; returns (root, the overrides that describe it)."""
    root = tmp_path_factory.mktemp("answering")
    overrides = [f"root={root}", f"dataset={small_dataset_dir}", "questions.max_per_group.train=2",
                 "questions.max_per_group.test=2", "collection.repeats.train=2", "collection.workers=1",
                 "collection.env.max_pushes=2"]
    collect = load_recipe("collect")
    for system in ("random", "no_manipulation"):        # the env's 224-px frames only (vqa=eqa: no answer camera)
        collect.collect(compose_recipe_config("collect", ["what=rollouts", *overrides, f"system={system}", "vqa=eqa",
                                                                   "progress=false"]))
    return root, overrides


@pytest.fixture
def dashboard_port():
    """A port where an HTTP server listens, as a Ray dashboard (8265) does: a TCP connection succeeds there, Ray's
    own connection retries for minutes (the Ray address checks' tests, unit and ray lane)."""
    import http.server
    import threading

    class Quiet(http.server.BaseHTTPRequestHandler):
        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("0.0.0.0", 0), Quiet)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield server.server_address[1]
    server.shutdown()
    server.server_close()

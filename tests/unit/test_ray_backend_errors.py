"""The Ray backend's clear errors, without Ray running: a missing extra names it, a wrong backend lists the
choices, an address where nothing listens, or no Ray head answers, says what to start within seconds, and no
worker to place is refused, each before anything is written."""

import socket
import sys
import time

import pytest

from conftest import compose_recipe_config, load_recipe
from mqa_rl.collectors import ray_pool
from mqa_rl.collectors.rollouts import collect_rollouts


def test_missing_ray_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)            # as if the extra were not installed
    with pytest.raises(ImportError, match=r"'ray' extra.*pip install -e '\.\[ray\]'"):
        ray_pool.import_ray()
    with pytest.raises(ImportError, match="'ray' extra"):
        with ray_pool.ray_session():
            pass


def test_a_wrong_backend_lists_the_choices(tmp_path):
    with pytest.raises(ValueError, match=r"collection.backend='cluster'.*\['local', 'ray'\]"):
        collect_rollouts(tmp_path / "x", dataset=str(tmp_path / "none"), policy={"kind": "random"}, split="test",
                         backend="cluster")
    assert not (tmp_path / "x").exists()


def test_nothing_listening_says_what_to_start():
    pytest.importorskip("ray")
    with pytest.raises(ConnectionError, match="ray start --head"):
        with ray_pool.ray_session("127.0.0.1:9"):
            pass


# ----------------------------------------------------------------------------- an address Ray would retry for minutes


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.timeout(60)
def test_a_port_that_is_no_ray_head_is_refused_within_seconds(dashboard_port):
    """Ray's GCS client retries a listening non-GCS port for minutes; the check asks it for a cluster id."""
    pytest.importorskip("ray")
    start = time.monotonic()
    with pytest.raises(ConnectionError, match=r"does not answer as a Ray head.*ray start --head.*8265"):
        with ray_pool.ray_session(f"127.0.0.1:{dashboard_port}"):
            pass
    assert time.monotonic() - start < 20


@pytest.mark.timeout(60)
def test_a_listener_that_never_answers_is_refused_within_the_timeout():
    pytest.importorskip("ray")
    with socket.socket() as silent:
        silent.bind(("0.0.0.0", 0))
        silent.listen()
        start = time.monotonic()
        with pytest.raises(ConnectionError, match="DEADLINE_EXCEEDED"):
            ray_pool.check_ray_address(f"127.0.0.1:{silent.getsockname()[1]}", timeout=2.0)
    assert time.monotonic() - start < 15


@pytest.mark.timeout(60)
def test_auto_is_checked_at_the_address_it_resolves_to(monkeypatch):
    pytest.importorskip("ray")
    monkeypatch.setenv("RAY_ADDRESS", f"127.0.0.1:{free_port()}")      # what `auto` resolves to first
    with pytest.raises(ConnectionError, match="nothing listens at ray.address='auto'"):
        ray_pool.check_ray_address("auto")


@pytest.mark.timeout(120)
@pytest.mark.parametrize("where", ["nothing", "dashboard"])
def test_train_dqn_on_ray_at_a_wrong_address_fails_at_once_writing_nothing(tmp_path, dashboard_port, where):
    """TorchRL's RayCollector calls ray.init itself: the recipe checks the address before out_dir exists, so the
    corrected command finds no half-made run folder to refuse."""
    pytest.importorskip("ray")
    port = free_port() if where == "nothing" else dashboard_port
    train_dqn = load_recipe("train_dqn")
    cfg = compose_recipe_config("train_dqn", ["profile=smoke", f"dataset={tmp_path}", "collector=ray",
                                              f"ray.address=127.0.0.1:{port}", f"out_dir={tmp_path / 'run'}"])
    start = time.monotonic()
    with pytest.raises(ConnectionError, match="nothing listens" if where == "nothing" else "does not answer as a Ray head"):
        train_dqn.train(cfg)
    assert time.monotonic() - start < 20
    assert not (tmp_path / "run").exists()


# ----------------------------------------------------------------------------- no actor to place
@pytest.mark.timeout(60)
def test_the_ray_backend_refuses_zero_workers_before_anything(tmp_path):
    """A local Ray started with 0 CPUs places no actor: each entry refuses workers < 1 at once, writing nothing."""
    ray = pytest.importorskip("ray")
    with pytest.raises(ValueError, match=r"collection.workers=0.*≥ 1"):
        collect_rollouts(tmp_path / "x", dataset=str(tmp_path / "none"), policy={"kind": "random"}, split="test",
                         backend="ray", workers=0)
    assert not (tmp_path / "x").exists()
    with pytest.raises(ValueError, match=r"workers=0.*≥ 1"):
        with ray_pool.ray_session(num_cpus=0):
            pass
    assert not ray.is_initialized()
    train_dqn = load_recipe("train_dqn")
    cfg = compose_recipe_config("train_dqn", ["profile=smoke", f"dataset={tmp_path}", "collector=ray",
                                              "collector.num_workers=0", f"out_dir={tmp_path / 'run'}"])
    with pytest.raises(ValueError, match=r"num_workers=0"):
        train_dqn.train(cfg)
    assert not (tmp_path / "run").exists()

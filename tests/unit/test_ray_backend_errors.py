"""The Ray backend's clear errors, without Ray running: a missing extra names it, a wrong backend lists the
choices, an address where nothing listens says what to start."""

import sys

import pytest

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

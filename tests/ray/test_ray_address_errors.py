"""Ray addresses and worker counts that Ray itself would wait on for minutes, on the two-node cluster: a worker
node's port (gRPC, but no head's GCS), a dashboard's (HTTP) and a port where nothing listens fail within seconds,
writing nothing, and the corrected command then runs in the same out_dir; no worker to place is refused at once."""

from __future__ import annotations

import socket
import time

import pytest

from conftest import compose_recipe_config, load_recipe
from mqa_rl.collectors.ray_pool import check_ray_address, ray_session

pytestmark = pytest.mark.ray


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def dqn_config(tmp_path, dataset, *overrides):
    return compose_recipe_config("train_dqn", ["profile=smoke", f"dataset={dataset}", "seed=3", "collector=ray",
                                               "collector.num_workers=2", f"out_dir={tmp_path / 'run'}", *overrides])




@pytest.mark.timeout(180)
def test_a_port_of_the_cluster_that_is_no_head_fails_within_seconds(ray_cluster, dashboard_port, small_dataset_dir,
                                                                     tmp_path):
    """A worker node's port (gRPC, no GCS) and a dashboard's (HTTP) pass a TCP check; the GCS probe refuses them."""
    with ray_session(ray_cluster) as ray:
        ports = [n["NodeManagerPort"] for n in ray.nodes() if n["Alive"]]
    check_ray_address(ray_cluster)                               # the head's address passes
    for port, said in [*((p, r"UNIMPLEMENTED") for p in ports), (dashboard_port, r"UNAVAILABLE.*8265")]:
        start = time.monotonic()
        with pytest.raises(ConnectionError, match=rf"does not answer as a Ray head's GCS \({said}"):
            with ray_session(f"127.0.0.1:{port}"):
                pass
        assert time.monotonic() - start < 10, port
    for port in (ports[0], dashboard_port):
        with pytest.raises(ConnectionError, match="does not answer as a Ray head"):
            load_recipe("train_dqn").train(dqn_config(tmp_path, small_dataset_dir, f"ray.address=127.0.0.1:{port}"))
        assert not (tmp_path / "run").exists()


@pytest.mark.timeout(600)
def test_train_dqn_at_a_dead_port_fails_at_once_and_the_corrected_command_runs(ray_cluster, small_dataset_dir, tmp_path):
    train_dqn = load_recipe("train_dqn")
    start = time.monotonic()
    with pytest.raises(ConnectionError, match="nothing listens at ray.address"):
        train_dqn.train(dqn_config(tmp_path, small_dataset_dir, f"ray.address=127.0.0.1:{free_port()}"))
    assert time.monotonic() - start < 10
    assert not (tmp_path / "run").exists()
    train_dqn.train(dqn_config(tmp_path, small_dataset_dir, f"ray.address={ray_cluster}", "collector.total_frames=16"))
    assert any((tmp_path / "run" / "checkpoints").iterdir())


@pytest.mark.timeout(120)
def test_zero_workers_on_a_local_ray_is_refused_at_once(small_dataset_dir, tmp_path):
    """A local Ray of 0 CPUs would place no actor and wait forever."""
    from mqa_rl.collectors.rollouts import collect_rollouts

    start = time.monotonic()
    with pytest.raises(ValueError, match=r"collection.workers=0.*≥ 1"):
        collect_rollouts(tmp_path / "rollouts", dataset=str(small_dataset_dir), policy={"kind": "random"},
                         split="train", backend="ray", workers=0)
    assert not (tmp_path / "rollouts").exists()
    with pytest.raises(ValueError, match=r"workers=0.*≥ 1"):
        load_recipe("evaluate_policy").main(compose_recipe_config("evaluate_policy", [
            f"dataset={small_dataset_dir}", "split=train", "difficulties=[easy]", "episodes_per_level=1",
            "policies=[random]", "video_episodes=0", "backend=ray", "workers=0", f"out_dir={tmp_path / 'eval'}"]))
    assert time.monotonic() - start < 30

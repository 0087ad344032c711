"""RayPool on the two-node cluster: every task's result exactly once, also when an actor's process dies, and
when more actors are asked for than the cluster has CPUs free (none is left holding tasks it never runs)."""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

import pytest

from mqa_rl.collectors.ray_pool import RayPool, ray_session

pytestmark = pytest.mark.ray


def square_or_die(task):
    """Kill this actor's process the first time ``task`` is the marked one (a marker file makes it once)."""
    value, marker = task
    if marker is not None and not Path(marker).exists():
        Path(marker).write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    import ray

    return value, value * value, os.getpid(), ray.get_runtime_context().get_node_id()


def test_pool_spreads_over_both_nodes_and_reruns_a_killed_task(ray_cluster, tmp_path):
    marker = str(tmp_path / "killed")
    tasks = [(i, marker if i == 3 else None) for i in range(12)]
    with ray_session(ray_cluster) as ray:
        ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])     # the workers cannot import tests/
        nodes = {n["NodeID"] for n in ray.nodes() if n["Alive"]}
        wait_for_free_cpus(ray, 2)
        pool = RayPool(2)
        try:
            ray.get([a.__ray_ready__.remote() for a in pool.actors], timeout=120)   # both run: both get tasks
            results = list(pool.imap_unordered(square_or_die, tasks))
            assert pool.deaths == 1                       # the marked task killed its actor once ...
            assert len(pool.actors) == 2                  # ... which was replaced
        finally:
            pool.terminate()
    assert sorted(r[0] for r in results) == list(range(12))          # none lost, none duplicated
    assert all(r[1] == r[0] * r[0] for r in results)
    killed = int(Path(marker).read_text())
    assert next(r[2] for r in results if r[0] == 3) != killed          # task 3 was run again by another actor
    assert len(nodes) == 2 and {r[3] for r in results} == nodes        # both nodes ran tasks


def wait_for_free_cpus(ray, n: int, timeout: float = 60.0) -> None:
    """Until the cluster has ``n`` CPUs free (a previous test's actors release theirs within seconds)."""
    deadline = time.time() + timeout
    while ray.available_resources().get("CPU", 0) < n and time.time() < deadline:
        time.sleep(0.2)
    assert ray.available_resources().get("CPU", 0) >= n, ray.available_resources()


def slow_square(value):
    time.sleep(0.2)
    return value, value * value


class Holder:
    """Takes a CPU of the cluster, as another job's actor would."""


@pytest.mark.timeout(300)
def test_more_workers_than_free_cpus_start_as_many_actors_as_fit_and_say_so(ray_cluster, capsys):
    with ray_session(ray_cluster) as ray:
        ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
        wait_for_free_cpus(ray, 2)
        pool = RayPool(8)                                # the cluster has 2 CPUs: 6 actors would never be placed
        try:
            started = len(pool.actors)
            results = list(pool.imap_unordered(slow_square, range(15)))
        finally:
            pool.terminate()
    assert started == 2
    assert sorted(r[0] for r in results) == list(range(15)) and all(r[1] == r[0] ** 2 for r in results)
    assert "RayPool: 8 actors asked for, the Ray cluster has CPUs free for 2: starting 2" in capsys.readouterr().out


@pytest.mark.timeout(300)
def test_an_actor_the_cluster_cannot_place_is_given_no_task(ray_cluster, capsys, monkeypatch):
    """Its CPUs taken after the pool looked (another job's actor): the running actor runs every task."""
    with ray_session(ray_cluster) as ray:
        ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
        wait_for_free_cpus(ray, 2)
        holder = ray.remote(num_cpus=1)(Holder).remote()
        ray.get(holder.__ray_ready__.remote(), timeout=120)                 # one of the two CPUs taken
        monkeypatch.setattr(ray, "available_resources", lambda: {"CPU": 2.0})   # as if still free when the pool looked
        pool = RayPool(2)
        try:
            results = list(pool.imap_unordered(slow_square, range(6)))
            running = len(pool.running)
        finally:
            pool.terminate()
            ray.kill(holder)
    assert running == 1
    assert sorted(r[0] for r in results) == list(range(6))
    assert "RayPool: 1 of 2 actors not running" in capsys.readouterr().out

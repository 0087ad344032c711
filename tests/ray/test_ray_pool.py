"""RayPool on the two-node cluster: every task's result exactly once, also when an actor's process dies."""

from __future__ import annotations

import os
import signal
import sys
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
        pool = RayPool(2)
        try:
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

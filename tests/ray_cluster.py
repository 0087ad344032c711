"""The ray lane's (tests/ray) two-node Ray cluster on this machine's loopback: a head and a second node, one
CPU each (``mqa_rl.collectors.ray_pool.loopback_cluster``), stopped at the end of the session. Registered in
conftest.py; Ray's settings are put in the environment here, before torchrl imports Ray."""

from __future__ import annotations

import os

import pytest

from mqa_rl.collectors.ray_pool import LOOPBACK_ENV

os.environ.update(LOOPBACK_ENV)


@pytest.fixture(scope="session")
def ray_cluster():
    """The cluster's address (host:port): two nodes of one CPU, joined by the recipes with ray.address=."""
    pytest.importorskip("ray", reason="the ray lane needs the 'ray' extra (pip install -e '.[ray]')")
    from mqa_rl.collectors.ray_pool import loopback_cluster

    with loopback_cluster(nodes=2, cpus_per_node=1) as address:
        yield address

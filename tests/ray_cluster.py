"""A real two-node Ray cluster on this machine's loopback for the ray lane (tests/ray): a head and a second node,
one CPU each (`ray start`, as on a real cluster), stopped at the end of the session. Registered in conftest.py;
Ray is imported only when a test asks for the cluster."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

RAY = str(Path(sys.executable).with_name("ray"))
# Ray 2.60 authenticates with a token (~/.ray/auth_token, made by the head): the nodes and the driver must agree,
# and Ray reads the mode once, when first imported (torchrl imports it): set here, as conftest.py loads
os.environ["RAY_AUTH_MODE"] = "token"
os.environ["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "1"      # two nodes on one machine (the lane's loopback cluster)
ENV = dict(os.environ)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _ray(*args: str) -> None:
    subprocess.run([RAY, *args], env=ENV, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, timeout=120)


def alive_nodes(ray) -> int:
    return sum(1 for n in ray.nodes() if n["Alive"])


@pytest.fixture(scope="session")
def ray_cluster():
    """The cluster's address (host:port): two nodes of one CPU, joined by the recipes with ray.address=."""
    ray = pytest.importorskip("ray", reason="the ray lane needs the 'ray' extra (pip install -e '.[ray]')")
    port = _free_port()
    address = f"127.0.0.1:{port}"
    common = ("--node-ip-address=127.0.0.1", "--num-cpus=1", "--disable-usage-stats")
    _ray("start", "--head", f"--port={port}", "--include-dashboard=false", *common)
    try:
        _ray("start", f"--address={address}", *common)
        ray.init(address=address, log_to_driver=False)
        try:
            deadline = time.time() + 60
            while alive_nodes(ray) < 2 and time.time() < deadline:
                time.sleep(1)
            assert alive_nodes(ray) == 2 and ray.cluster_resources().get("CPU") == 2
        finally:
            ray.shutdown()
        yield address
    finally:
        subprocess.run([RAY, "stop", "--force"], env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120)

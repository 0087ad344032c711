"""tools/debian_mirror.sh: bookworm-backports must come from the mirror apt already uses."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO

SCRIPT = REPO / "tools" / "debian_mirror.sh"

DEB822 = """\
Types: deb
# a comment inside the stanza
URIs: http://127.0.0.1:3142/debian
Suites: bookworm bookworm-updates
Components: main contrib
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: http://127.0.0.1:3142/debian-security
Suites: bookworm-security
Components: main
"""

DEB822_SECURITY_FIRST = """\
Types: deb
URIs: file:///srv/security
Suites: bookworm-security
Components: main

Types: deb-src deb
URIs: file:///srv/mirror/debian
Suites: bookworm
Components: non-free main
"""

THIRD_PARTY_DEB822 = """\
Types: deb
URIs: http://127.0.0.2/node_20.x
Suites: nodistro
Components: main
"""

CLASSIC = """\
# deb http://127.0.0.3/commented bookworm main
deb [arch=amd64 signed-by=/usr/share/keyrings/debian-archive-keyring.gpg] http://[::1]/debian bookworm main non-free-firmware
deb http://[::1]/debian-security bookworm-security main
"""

CLASSIC_PLAIN = "deb http://127.0.0.4/debian/ bookworm main contrib\n"


def derive(tmp_path: Path, sources: dict[str, str], classic: str | None = None) -> subprocess.CompletedProcess:
    d = tmp_path / "sources.list.d"
    d.mkdir()
    for name, text in sources.items():
        (d / name).write_text(text)
    listfile = tmp_path / "sources.list"
    if classic is not None:
        listfile.write_text(classic)
    return subprocess.run(["bash", str(SCRIPT), str(d), str(listfile)], capture_output=True, text=True)


@pytest.mark.parametrize(
    ("sources", "classic", "expected"),
    [
        ({"debian.sources": DEB822}, None, "http://127.0.0.1:3142/debian"),
        ({"debian.sources": DEB822_SECURITY_FIRST}, None, "file:///srv/mirror/debian"),
        ({"a-nodesource.sources": THIRD_PARTY_DEB822, "debian.sources": DEB822}, None, "http://127.0.0.1:3142/debian"),
        ({}, CLASSIC, "http://[::1]/debian"),
        ({"nodesource.sources": THIRD_PARTY_DEB822}, CLASSIC_PLAIN, "http://127.0.0.4/debian/"),
        ({"extra.list": CLASSIC_PLAIN}, "", "http://127.0.0.4/debian/"),
    ],
)
def test_mirror_is_derived_from_the_configured_debian_entry(tmp_path, sources, classic, expected):
    out = derive(tmp_path, sources, classic)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == expected


def test_no_debian_entry_fails(tmp_path):
    out = derive(tmp_path, {"nodesource.sources": THIRD_PARTY_DEB822}, "deb http://127.0.0.5/x nodistro main\n")
    assert out.returncode == 1 and out.stdout == ""


def test_bootstrap_names_no_mirror_host():
    root = SCRIPT.parents[1]
    for path in [root / "tools" / "bootstrap.sh", SCRIPT, root / "README.md", root / "docs" / "platform.md"]:
        assert "debian.org" not in path.read_text(), path


def test_bootstrap_refuses_a_full_disk_before_installing(tmp_path):
    """Too little free space is named up front; no package is installed and no stamp written,
    so the next run (with space freed) installs from scratch."""
    root = REPO
    venv = tmp_path / "venv"
    env = {**os.environ, "PYTHON": sys.executable, "MQA_VENV": str(venv), "MQA_MIN_FREE_GB": "1000000"}
    out = subprocess.run(["bash", str(root / "tools" / "bootstrap.sh")], env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 1
    assert "GB free on the disk of" in out.stderr and "installing the packages needs about 1000000 GB" in out.stderr
    assert "installing pinned packages" not in out.stderr
    assert not (venv / ".mqa-lock-stamp").exists()
    assert not (venv / "pip-install.log").exists()

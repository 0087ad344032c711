"""Writes killed with SIGKILL leave hidden folders; the loader and the next generation recover them."""

import os
import subprocess
import sys
import textwrap

import pytest

from mqa_rl.data import DatasetError, MQADataset, generate_dataset
from mqa_rl.data.storage import read_verified, recover_leftovers, write_dataset_atomically

KILLED_WHILE_WRITING = """
    class DiesHalfWay(dict):                       # the process is killed after the first file
        def items(self):
            yield "a.txt", b"new"
            os.kill(os.getpid(), signal.SIGKILL)
    write_dataset_atomically(out, DiesHalfWay(), {})
"""
KILLED_BETWEEN_RENAMES = """
    rename = os.rename
    def rename_then_die(src, dst):                 # killed right after the old dataset was moved aside
        rename(src, dst)
        if ".old-" in str(dst):
            os.kill(os.getpid(), signal.SIGKILL)
    os.rename = rename_then_die
    write_dataset_atomically(out, {"a.txt": b"new"}, {}, overwrite=True)
"""


def _killed(out, body):
    script = "import os, signal, sys\nfrom pathlib import Path\n" \
             "from mqa_rl.data.storage import write_dataset_atomically\nout = Path(sys.argv[1])\n" + textwrap.dedent(body)
    proc = subprocess.run([sys.executable, "-c", script, str(out)], capture_output=True, text=True)
    assert proc.returncode == -9, proc.stderr


def _hidden(out):
    return sorted(p.name.split("-")[0] for p in out.parent.iterdir() if p.name.startswith(f".{out.name}."))


def test_unfinished_write_is_removed_by_the_loader(tmp_path):
    out = tmp_path / "ds"
    _killed(out, KILLED_WHILE_WRITING)
    assert _hidden(out) == [".ds.tmp"] and not out.exists()
    with pytest.warns(UserWarning, match="unfinished dataset write"), pytest.raises(DatasetError, match="does not exist"):
        MQADataset(out)
    assert _hidden(out) == []


def test_unfinished_write_is_removed_by_the_next_generation(tmp_path):
    out = tmp_path / "ds"
    _killed(out, KILLED_WHILE_WRITING)
    with pytest.warns(UserWarning, match="unfinished dataset write"):
        ds = generate_dataset(out, num_scenes={"easy": 1}, objects_per_scene={"easy": 2})
    assert _hidden(out) == [] and len(ds.scenes) == 1


def test_overwrite_killed_between_renames_restores_the_old_dataset(tmp_path):
    out = tmp_path / "ds"
    write_dataset_atomically(out, {"a.txt": b"old"}, {})
    _killed(out, KILLED_BETWEEN_RENAMES)
    assert _hidden(out) == [".ds.old", ".ds.tmp"] and not out.exists()
    with pytest.warns(UserWarning) as record:
        _, data = read_verified(out)
    assert data == {"a.txt": b"old"} and _hidden(out) == []
    assert any("restored" in str(w.message) for w in record) and any("removed" in str(w.message) for w in record)
    with pytest.raises(FileExistsError, match="overwrite"):       # the next plain write sees the restored one
        write_dataset_atomically(out, {"a.txt": b"new"}, {})


def test_old_copy_of_a_finished_overwrite_is_removed_and_live_writers_are_left_alone(tmp_path):
    out = tmp_path / "ds"
    write_dataset_atomically(out, {"a.txt": b"new"}, {})
    (tmp_path / ".ds.old-4194305-deadbeef").mkdir()               # no such pid: its writer is gone
    live = tmp_path / f".ds.tmp-{os.getppid()}-cafe0001"          # a writer that still runs
    live.mkdir()
    with pytest.warns(UserWarning, match="previous dataset"):
        recover_leftovers(out)
    assert _hidden(out) == [".ds.tmp"] and live.exists()
    assert read_verified(out)[1] == {"a.txt": b"new"}


def test_a_file_is_not_reported_as_a_missing_folder(tmp_path):
    f = tmp_path / "dataset.zip"
    f.write_bytes(b"PK")
    with pytest.raises(DatasetError, match="is a file"):
        MQADataset(f)


def test_a_write_that_fails_between_renames_puts_the_old_dataset_back(tmp_path, monkeypatch):
    out = tmp_path / "ds"
    write_dataset_atomically(out, {"a.txt": b"old"}, {})
    rename = os.rename

    def second_rename_fails(src, dst):
        if ".tmp-" in str(src):
            raise OSError("disk gone")
        rename(src, dst)

    monkeypatch.setattr(os, "rename", second_rename_fails)
    with pytest.raises(OSError, match="disk gone"):
        write_dataset_atomically(out, {"a.txt": b"new"}, {}, overwrite=True)
    monkeypatch.undo()
    assert read_verified(out)[1] == {"a.txt": b"old"} and _hidden(out) == []

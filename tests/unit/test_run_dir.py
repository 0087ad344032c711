"""A training recipe's out_dir: one writer, and what a run killed mid-save left behind goes."""

import pytest

from mqa_rl.training.run_dir import RunLock


def test_the_lock_removes_stages_a_killed_save_left_and_keeps_checkpoints(tmp_path):
    ckpts = tmp_path / "run" / "checkpoints"
    stage = ckpts / ".checkpoint-000000000012.stage-0123abcd"
    (stage / "components").mkdir(parents=True)
    (stage / "components" / "big.memmap").write_bytes(b"\0" * 1024)
    (ckpts / "checkpoint-000000000008").mkdir()
    (tmp_path / "run" / "notes.stage-1").write_text("a user's file, not a checkpoint stage")
    with RunLock(tmp_path / "run", "train_dqn.py"):
        assert not stage.exists()
        assert (ckpts / "checkpoint-000000000008").is_dir() and (tmp_path / "run" / "notes.stage-1").exists()
        with pytest.raises(RuntimeError, match="another train_dqn.py run is writing"):
            with RunLock(tmp_path / "run", "train_dqn.py"):
                pass

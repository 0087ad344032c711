"""The recipes run end to end from the command line (tiny budgets), as a user runs them."""

import subprocess
import sys

import pytest

from conftest import REPO as ROOT


def _run(*args, cwd):
    out = subprocess.run([sys.executable, *args], cwd=cwd, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return out.stdout


@pytest.mark.timeout(900)
def test_make_dataset_then_a_few_random_episodes(tmp_path):
    ds = tmp_path / "mqa"
    text = _run(str(ROOT / "recipes" / "make_dataset.py"), f"dataset.out_dir={ds}",
                "dataset.num_scenes={easy: 1, medium: 0, hard: 1}", f"plot={tmp_path / 'stats.png'}", cwd=tmp_path)
    assert "2 scenes" in text and "COUNTING answers" in text and (tmp_path / "stats.png").stat().st_size > 0
    again = _run(str(ROOT / "recipes" / "make_dataset.py"), f"dataset.out_dir={ds}", f"plot={tmp_path / 's2.png'}", cwd=tmp_path)
    assert "already" in again                                   # a second run keeps the dataset
    (ds / "scenes.json").write_text("[]")
    broken = subprocess.run([sys.executable, str(ROOT / "recipes" / "make_dataset.py"), f"dataset.out_dir={ds}"],
                            cwd=tmp_path, capture_output=True, text=True)
    assert broken.returncode != 0 and "checksum" in broken.stderr and "overwrite" in broken.stderr
    _run(str(ROOT / "recipes" / "make_dataset.py"), f"dataset.out_dir={ds}", "dataset.overwrite=true",
         "dataset.num_scenes={easy: 1, medium: 0, hard: 1}", f"plot={tmp_path / 's3.png'}", cwd=tmp_path)
    out_dir = tmp_path / "episodes"
    text = _run(str(ROOT / "recipes" / "collect.py"), "what=episodes", f"dataset={ds}", "episodes=1", "env.difficulties=[easy]",
                "video_format=gif", f"out_dir={out_dir}", "reward=local", "reward.question_weights.local_occlusion=0.7",
                cwd=tmp_path)
    assert "episode 0:" in text and "reward" in text and "'local_occlusion': 0.7" in text
    assert (out_dir / "episode_0.gif").stat().st_size > 0 and (out_dir / "episodes.log").exists()

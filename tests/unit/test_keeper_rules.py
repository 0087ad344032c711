"""benchmarks/keeper_rules.py compare --against: two policies' recordings of the same questions, paired."""

import subprocess
import sys
from pathlib import Path

import torch

from mqa_rl.modules.kept_frame import EXPECTED
from mqa_rl.modules.perceived_count import READING

REPO = Path(__file__).resolve().parents[2]


def episode(scene: int, targets: int, seen: list[int], expected: list[float], counting: bool = True) -> dict:
    reading = torch.zeros(len(seen), len(READING))
    reading[:, EXPECTED] = torch.tensor(expected)
    return {"reading": reading, "seen": torch.tensor(seen), "targets": torch.tensor(targets),
            "counting": counting, "scene": scene}


def write(folder: Path, episodes: list[dict]) -> str:
    folder.mkdir(parents=True)
    torch.save({"meta": {"level": "hard"}, "episodes": episodes}, folder / "hard.pt")
    return str(folder)


def compare(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(REPO / "benchmarks" / "keeper_rules.py"), "compare", *args],
                          capture_output=True, text=True, cwd=REPO)


def test_policies_are_paired_on_the_frame_each_keeps(tmp_path):
    # A keeps the frame where 2 of 2 targets show (largest expected count) in both scenes; B keeps a frame showing 1
    a = write(tmp_path / "a", [episode(0, 2, [1, 2], [1.0, 2.0]), episode(1, 2, [1, 2], [1.0, 2.0]),
                               episode(1, 0, [0, 0], [0.1, 0.0], counting=False)])
    b = write(tmp_path / "b", [episode(0, 2, [1, 2], [2.0, 1.0]), episode(1, 2, [1, 1], [1.0, 2.0]),
                               episode(1, 0, [0, 0], [0.0, 0.0], counting=False)])
    out = compare(a, "--against", b)
    assert out.returncode == 0, out.stderr
    lines = {line.split(" A ")[0].strip(): line for line in out.stdout.splitlines() if "perfect counter on" in line}
    assert "2 COUNTING episodes over 2 scenes" in out.stdout
    assert "A 1.000  B 0.000  A − B +1.000" in lines["perfect counter on the shipped rule's frame"]
    assert "A 1.000  B 0.500  A − B +0.500" in lines["perfect counter on the best frame"]
    assert "A 0.000  B 0.000  A − B +0.000" in lines["perfect counter on the first frame"]


def test_recordings_of_other_questions_are_refused(tmp_path):
    a = write(tmp_path / "a", [episode(0, 2, [1, 2], [1.0, 2.0])])
    b = write(tmp_path / "b", [episode(3, 2, [1, 2], [1.0, 2.0])])
    out = compare(a, "--against", b)
    assert out.returncode != 0
    assert "hold different questions" in out.stderr and "same --dataset, --episodes and --seed" in out.stderr
    out = compare(a, "--against", str(tmp_path / "missing"))
    assert out.returncode != 0 and "no <level>.pt record file in" in out.stderr and "missing" in out.stderr

"""recipes/pipeline.py pipeline=reward_variants: the paper's three rewards as DQfD continuations of a finished student,
run as a user runs it. Its refusals come before anything is written."""

import subprocess
import sys

from conftest import REPO, compose_recipe_config


def run_variants(tmp_path, *overrides):
    return subprocess.run([sys.executable, str(REPO / "recipes" / "pipeline.py"), "pipeline=reward_variants",
                           *map(str, overrides)], cwd=tmp_path, capture_output=True, text=True, timeout=300)


def finished_student(tmp_path):
    """A folder shaped as a finished pipeline=student root: a checkpoint and both demonstration sets' demos.json."""
    student = tmp_path / "student"
    (student / "dqn" / "checkpoints" / "checkpoint-000000000008").mkdir(parents=True)
    (student / "dqn" / "config.yaml").write_text("seed: 0\ncollector: {total_frames: 8}\n")
    (student / "demos_1").mkdir()
    (student / "demos_1" / "demos.json").write_text("{}")
    return student


def test_it_refuses_a_folder_without_a_finished_student(tmp_path):
    (tmp_path / "student" / "dqn").mkdir(parents=True)
    done = run_variants(tmp_path, f"student={tmp_path / 'student'}", f"root={tmp_path / 'out'}")
    assert done.returncode == 2 and "holds no finished imitation student" in done.stderr
    assert "python recipes/pipeline.py pipeline=student" in done.stderr
    assert not (tmp_path / "out").exists()


def test_it_refuses_bad_frames_unknown_variants_and_options_before_writing(tmp_path):
    student, out = finished_student(tmp_path), tmp_path / "out"
    done = run_variants(tmp_path, f"student={student}", f"root={out}", "frames=ten")
    assert done.returncode == 2 and "frames must be a positive whole number, got 'ten'" in done.stderr
    done = run_variants(tmp_path, f"student={student}", f"root={out}", "frames=0")
    assert done.returncode == 2 and "frames must be a positive whole number, got '0'" in done.stderr
    done = run_variants(tmp_path, f"student={student}", f"root={out}", "frames=100", "variants=[global,lokal]")
    assert done.returncode == 2 and "unknown reward 'lokal'" in done.stderr and "global_local" in done.stderr
    done = run_variants(tmp_path, f"student={student}", f"root={out}", "framez=100")
    assert done.returncode == 2 and "pipeline=reward_variants has no option 'framez': its options are" in done.stderr
    assert not out.exists()


def test_the_variants_continue_the_students_network_with_a_gentle_rl_phase():
    """The continuation must build the student's network (its checkpoint loads), and only the RL phase's step size
    and demonstration weight differ: at the student's 5e-4 / 0.5 the RL phase undid the imitation."""
    student = compose_recipe_config("train_dqn", ["profile=student"])
    variant = compose_recipe_config("train_dqn", ["profile=dqfd", "reward=local"])
    assert variant.model == student.model and variant.env == student.env and variant.buffer == student.buffer
    assert variant.optim.lr == 1e-4 < student.optim.lr and variant.demos.weight == 2.0 > student.demos.weight
    assert {k: v for k, v in variant.demos.items() if k != "weight"} == {k: v for k, v in student.demos.items() if k != "weight"}


def test_it_refuses_an_unknown_own_stop_setting_before_writing(tmp_path):
    """own_stop=false (no stop fitted: the budget-and-kept-frame system) or true; anything else is refused at once,
    not after minutes of training when the stop step comes."""
    student = finished_student(tmp_path)
    done = run_variants(tmp_path, f"student={student}", f"root={tmp_path / 'out'}", "frames=100", "variants=[countable]",
                        "own_stop=no")
    assert done.returncode == 2 and "own_stop must be true or false" in done.stderr and "got 'no'" in done.stderr
    assert not (tmp_path / "out").exists()

"""tools/train_reward_variants.sh: the paper's three rewards as DQfD continuations of a finished student. Its
refusals come before anything is written."""

import os
import subprocess

from conftest import REPO, compose_recipe_config


def run_variants(*args, **env):
    return subprocess.run(["bash", str(REPO / "tools/train_reward_variants.sh"), *map(str, args)],
                          env={**os.environ, **env}, capture_output=True, text=True, timeout=120)


def test_it_refuses_a_folder_without_a_finished_student(tmp_path):
    (tmp_path / "student" / "dqn").mkdir(parents=True)
    done = run_variants(tmp_path / "student", tmp_path / "out")
    assert done.returncode == 2 and "holds no finished imitation student" in done.stderr
    assert "bash tools/train_student.sh" in done.stderr
    assert not (tmp_path / "out").exists()


def test_it_refuses_bad_frames_and_unknown_variants_before_writing(tmp_path):
    student = tmp_path / "student"
    (student / "dqn" / "checkpoints" / "checkpoint-000000000008").mkdir(parents=True)
    (student / "demos_1").mkdir()
    (student / "demos_1" / "demos.json").write_text("{}")
    done = run_variants(student, tmp_path / "out", "ten")
    assert done.returncode == 2 and "FRAMES must be a positive integer" in done.stderr
    done = run_variants(student, tmp_path / "out", 0)
    assert done.returncode == 2 and "FRAMES must be a positive integer" in done.stderr
    done = run_variants(student, tmp_path / "out", 100, MQA_VARIANTS="global lokal")
    assert done.returncode == 2 and "unknown variant 'lokal'" in done.stderr
    assert not (tmp_path / "out").exists()


def test_the_variants_continue_the_students_network_with_a_gentle_rl_phase():
    """The continuation must build the student's network (its checkpoint loads), and only the RL phase's step size
    and demonstration weight differ: at the student's 5e-4 / 0.5 the RL phase undid the imitation."""
    student = compose_recipe_config("train_dqn", ["profile=student"])
    variant = compose_recipe_config("train_dqn", ["profile=dqfd", "reward=local"])
    assert variant.model == student.model and variant.env == student.env and variant.buffer == student.buffer
    assert variant.optim.lr == 1e-4 < student.optim.lr and variant.demos.weight == 2.0 > student.demos.weight
    assert {k: v for k, v in variant.demos.items() if k != "weight"} == {k: v for k, v in student.demos.items() if k != "weight"}


def test_it_refuses_an_unknown_own_stop_setting_before_writing(tmp_path):
    """MQA_OWN_STOP=0 (no stop fitted: the budget-and-kept-frame system) or 1; anything else is refused at once,
    not after minutes of training when the stop step comes."""
    student = tmp_path / "student"
    (student / "dqn" / "checkpoints" / "checkpoint-000000000008").mkdir(parents=True)
    (student / "dqn" / "config.yaml").write_text("seed: 0\ncollector: {total_frames: 8}\n")
    (student / "demos_1").mkdir()
    (student / "demos_1" / "demos.json").write_text("{}")
    done = run_variants(student, tmp_path / "out", 100, MQA_VARIANTS="countable", MQA_OWN_STOP="no")
    assert done.returncode == 2 and "MQA_OWN_STOP must be 1" in done.stderr and "got 'no'" in done.stderr
    assert not (tmp_path / "out").exists()

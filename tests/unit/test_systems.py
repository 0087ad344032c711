"""The one registry of MQA systems (recipes/conf/systems.yaml): every recipe that names a system composes the same
entries, every entry is a policy spec that checks, the ids the main job names exist, and a bad id is refused naming
the known ones."""

import pytest
from conftest import compose_recipe_config, load_recipe, system_registry

from mqa_rl.modules.systems import system_spec, systems_by_id, table3_systems

MAIN_JOB = tuple(compose_recipe_config("pipeline", ["pipeline=main"]).report)     # tools/main.sh's systems


@pytest.mark.parametrize("recipe", ["collect what=rollouts", "collect what=demonstrations", "train_vqa", "evaluate",
                                    "pretrain part=vqa_encoder", "evaluate_policy", "demo"])
def test_every_recipe_reads_the_one_registry(recipe):
    from omegaconf import OmegaConf

    name, *overrides = recipe.split()
    assert OmegaConf.to_container(compose_recipe_config(name, overrides).systems) == system_registry()


def test_every_entry_is_a_policy_spec_and_the_main_jobs_ids_are_there():
    systems = system_registry()
    for name in systems:
        assert "table3" not in system_spec(systems, name)                  # descriptive keys are not part of the spec
    assert set(MAIN_JOB) <= set(systems)
    assert system_spec(systems, "dqn_countable_budget_kept") == {
        "kind": "dqn", "run": "checkpoints/dqn_countable", "stop_margin": float("inf"),
        "kept_frame": "checkpoints/vqa_counting/perception.pt"}
    table3 = table3_systems(systems)
    assert set(MAIN_JOB) <= set(table3) and "image_teacher" not in table3 and "random_masked" not in table3


def test_a_bad_id_or_kind_is_refused_naming_what_is_known():
    systems = system_registry()
    with pytest.raises(ValueError, match="unknown system 'privilegd'.*privileged.*recipes/conf/systems.yaml"):
        system_spec(systems, "privilegd")
    with pytest.raises(ValueError, match="kind 'dqn'.*random, random_masked"):
        systems_by_id(systems, ["random", "dqn_local"], kinds=("random", "random_masked", "none"))
    with pytest.raises(ValueError, match="unknown policy option"):
        system_spec({"mine": {"kind": "random", "stop_critc": "x"}}, "mine")


def test_a_profile_or_an_override_points_an_entry_elsewhere_keeping_the_rest():
    quick = compose_recipe_config("train_vqa", ["answering=quick"]).systems.dqn_local
    assert dict(quick) == {"kind": "dqn", "run": "runs/quick/dqn_local"}
    moved = compose_recipe_config("evaluate", ["systems.dqn_student.run=elsewhere"]).systems.dqn_student
    assert dict(moved) == {"kind": "dqn", "run": "elsewhere", "stop_critic": "checkpoints/stop_geometric_student"}


def test_evaluate_policy_takes_a_dqn_system_as_its_greedy_policy():
    as_greedy = load_recipe("evaluate_policy").as_greedy
    cfg = as_greedy(compose_recipe_config("evaluate_policy", ["system=dqn_countable_budget_kept"]))
    assert (cfg.run, cfg.stop_margin, cfg.stop_critic, cfg.kept_frame, cfg.system) == (
        "checkpoints/dqn_countable", float("inf"), None, "checkpoints/vqa_counting/perception.pt", None)
    with pytest.raises(ValueError, match="give system= or those"):
        as_greedy(compose_recipe_config("evaluate_policy", ["system=dqn_student", "run=runs/local"]))
    with pytest.raises(ValueError, match="kind 'none'.*dqn_countable"):
        as_greedy(compose_recipe_config("evaluate_policy", ["system=no_manipulation"]))


def test_the_default_answering_vqa_is_the_counting_one_and_its_rollouts_carry_its_answer_camera():
    assert compose_recipe_config("train_vqa", []).vqa.name == "counting"
    assert compose_recipe_config("evaluate", []).vqa.name == "counting"
    assert compose_recipe_config("collect", ["what=rollouts"]).collection.env.answer_size == 448
    assert compose_recipe_config("collect", ["what=rollouts", "vqa=eqa"]).collection.env.answer_size is None
    assert compose_recipe_config("train_vqa", ["vqa=eqa"]).out_dir.endswith("counting-eqa/random")


def test_collect_demonstrations_takes_its_teacher_from_the_registry():
    """teacher=<id>: the options its demonstrations record, every one filled (the image teacher's are the values the
    recipe's own oracle block held before the registry); an oracle.<option> overrides the teacher's."""
    teacher_options = load_recipe("collect").teacher_options
    compose = lambda *o: teacher_options(compose_recipe_config("collect", ["what=demonstrations", *o]))    # noqa: E731
    image = {"lookahead": 1, "min_visible_px": 20, "min_visible_fraction": 0.3, "order": "visible_first",
             "geometry": "visible", "refine_radius": 0, "require_gain": False, "max_tries_per_occluder": 2}
    assert compose() == image
    assert compose("teacher=refined_teacher") == compose("oracle.refine_radius=1") == {**image, "refine_radius": 1}
    assert compose("teacher=countable_teacher") == {**image, "min_visible_fraction": 0.0, "order": "least_visible",
                                                    "geometry": "full", "refine_radius": 1, "require_gain": True}
    with pytest.raises(ValueError, match="kind 'random'.*image_teacher"):
        compose("teacher=random")

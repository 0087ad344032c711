"""The step runner of recipes/pipeline.py (mqa_rl.pipelines): steps in order, a line each with the time, a done step
skipped, a failing step stopping the pipeline with its command, and every refusal (an unknown pipeline or option, a
wrong value, a missing input) before any step runs, saying what to do. The steps here are tiny scripts standing in
for recipes; the pipelines of recipes/conf/pipeline/ are composed as Hydra composes them."""

import sys

import pytest
from omegaconf import OmegaConf

from conftest import REPO, compose_recipe_config
from mqa_rl.pipelines import PipelineRefused, StepFailed, check_command_line, plan, run_pipeline

CONF = REPO / "recipes" / "conf"
RECIPES = REPO / "recipes"

TOUCH = """import sys
from pathlib import Path
args = dict(a.split("=", 1) for a in sys.argv[1:])
Path(args["out"]).parent.mkdir(parents=True, exist_ok=True)
Path(args["out"]).write_text(" ".join(sys.argv[1:]))
"""


@pytest.fixture
def recipes(tmp_path):
    """A recipes folder of stand-ins: touch.py writes its arguments to out=, fail.py exits 3."""
    folder = tmp_path / "recipes"
    (folder / "conf").mkdir(parents=True)
    (folder / "touch.py").write_text(TOUCH)
    (folder / "fail.py").write_text("import sys\nprint('something went wrong')\nsys.exit(3)\n")
    return folder


def pipeline(tmp_path, steps, **options):
    return OmegaConf.create({"root": str(tmp_path / "out"), **options, "steps": steps})


def test_steps_run_in_order_with_their_time_and_a_done_step_is_skipped(tmp_path, recipes):
    cfg = pipeline(tmp_path, [
        {"say": "first -> ${root}/a", "run": "touch", "args": ["out=${root}/a", {"x": None}, ["y=1", "z=2"]],
         "done": "${root}/a"},
        {"say": "second", "run": "touch", "args": ["out=${root}/b"]},
        {"say": "finished: ${root}"}])
    lines = []
    record = run_pipeline(cfg, recipes, echo=lines.append)
    assert [r["status"] for r in record] == ["ran", "ran", "said"]
    assert (tmp_path / "out" / "a").read_text() == f"out={tmp_path / 'out' / 'a'} x=null y=1 z=2"
    assert lines[0] == f"=== [0 min 0 s] first -> {tmp_path / 'out'}/a" and lines[2].endswith(f"finished: {tmp_path / 'out'}")
    lines.clear()
    record = run_pipeline(cfg, recipes, echo=lines.append)      # again: the first step's output is there
    assert [r["status"] for r in record] == ["done", "ran", "said"]
    assert "first" in lines[0] and "done already" in lines[0] and "skipped" in lines[0]


def test_a_failing_step_stops_the_pipeline_naming_its_command(tmp_path, recipes):
    cfg = pipeline(tmp_path, [{"say": "breaks", "run": "fail", "args": ["k=v"]},
                              {"say": "never", "run": "touch", "args": ["out=${root}/never"]}])
    lines = []
    with pytest.raises(StepFailed) as failed:
        run_pipeline(cfg, recipes, echo=lines.append)
    message = str(failed.value)
    assert "step 'breaks' failed" in message and "exit code 3" in message and f"{recipes / 'fail.py'} k=v" in message
    assert "run the same pipeline command again" in message
    assert not (tmp_path / "out" / "never").exists() and len(lines) == 1


def test_parallel_steps_for_each_and_switched_off_steps(tmp_path, recipes):
    cfg = pipeline(tmp_path, [
        {"say": "both at once", "parallel": [{"run": "touch", "args": ["out=${root}/p0"], "done": "${root}/p0"},
                                             {"run": "touch", "args": ["out=${root}/p1"]}]},
        {"for_each": "${variants}", "steps": [{"say": "variant ${each}", "run": "touch", "args": ["out=${root}/${each}"]}]},
        {"say": "only with test", "run": "touch", "args": ["out=${root}/test"], "when": "${test}"},
        {"say": "not with stop", "run": "touch", "args": ["out=${root}/nostop"], "unless": "${stop}"}],
        variants=["global", "local"], test=None, stop=True)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "p0").write_text("done before")
    record = run_pipeline(cfg, recipes, echo=lambda line: None)
    assert [r["status"] for r in record] == ["ran", "ran", "ran", "off", "off"]
    assert (tmp_path / "out" / "p0").read_text() == "done before" and (tmp_path / "out" / "p1").exists()
    assert (tmp_path / "out" / "global").exists() and (tmp_path / "out" / "local").exists()
    assert not (tmp_path / "out" / "test").exists() and not (tmp_path / "out" / "nostop").exists()


def test_an_unknown_pipeline_or_option_is_refused_saying_what_there_is():
    with pytest.raises(PipelineRefused, match=r"pipeline=studnt: no such pipeline; choose one of answering, "
                                              r"encoder_scenes, main, reward_variants, student, table3"):
        check_command_line(CONF, ["pipeline=studnt"])
    with pytest.raises(PipelineRefused, match=r"pipeline=student has no option 'teachr': its options are root, seed, "
                                              r"teacher, .* \(recipes/conf/pipeline/student.yaml says what each does\)"):
        check_command_line(CONF, ["pipeline=student", "teachr=refined"])
    check_command_line(CONF, ["-m", "pipeline=student", "teacher=refined", "--cfg", "job", "hydra.run.dir=x", "+new=1"])
    check_command_line(CONF, ["teacher=refined"])              # no pipeline: Hydra lists them


def test_a_step_naming_no_recipe_is_refused_before_any_step(tmp_path, recipes):
    cfg = pipeline(tmp_path, [{"say": "ok", "run": "touch", "args": ["out=${root}/a"]}, {"say": "typo", "run": "tuoch"}])
    with pytest.raises(PipelineRefused, match="run: tuoch names no recipe"):
        run_pipeline(cfg, recipes, echo=lambda line: None)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("overrides, message", [
    (["pipeline=student", "teacher=bogus"], "teacher=bogus: choose one of image, refined, countable"),
    (["pipeline=student", "own_stop=no"], "own_stop must be true or false, got 'no'"),
    (["pipeline=student", "test_episodes=0"], "test_episodes must be a positive whole number or null, got '0'"),
    (["pipeline=reward_variants", "frames=ten"], "frames must be a positive whole number, got 'ten'"),
    (["pipeline=reward_variants", "variants=[global,lokal]"], "variants: unknown reward 'lokal': choose among"),
    (["pipeline=reward_variants"], "give student=<the root of a finished `python recipes/pipeline.py pipeline=student`>"),
    (["pipeline=table3", "vqa_model=counting"], "vqa_model=counting: choose one of eqa, classes"),
])
def test_a_wrong_value_is_refused_before_any_step_saying_what_to_do(overrides, message, tmp_path):
    cfg = compose_recipe_config("pipeline", [*overrides, f"root={tmp_path / 'root'}"])
    lines = []
    with pytest.raises(PipelineRefused, match=message.replace("[", r"\[").replace("(", r"\(").replace(")", r"\)")):
        run_pipeline(cfg, RECIPES, python=sys.executable, echo=lines.append)
    assert lines == [] and not (tmp_path / "root").exists()


def test_every_pipeline_plans_steps_of_existing_recipes(tmp_path):
    """Each pipeline of recipes/conf/pipeline resolves into steps that name recipes there; the student's follows its
    teacher (reward and the stop's measure) and the switches."""
    for name in ("student", "answering", "table3", "encoder_scenes", "main"):
        assert plan(compose_recipe_config("pipeline", [f"pipeline={name}"]), RECIPES)
    steps = plan(compose_recipe_config("pipeline", ["pipeline=student", "teacher=countable", "own_stop=false",
                                                    "test_episodes=30", 'dqn=["demos.pretrain_updates=10"]']), RECIPES)
    student = next(s for s in steps if s.run == "train_dqn")
    assert "reward=countable" in student.args and student.args[-1] == "demos.pretrain_updates=10"
    assert [s.run for s in steps if s.active] == ["make_dataset", None, "train_dqn", "evaluate_policy", None]
    evaluation = next(s for s in steps if s.active and s.run == "evaluate_policy")
    assert "stop_margin=inf" in evaluation.args and "baseline_from=null" in evaluation.args


def test_a_mapping_argument_is_written_as_hydra_reads_it_back():
    """{key: value} steps' arguments: null, booleans, numbers, lists as such; a string that would read as something
    else (a number, null, spaces, quotes) quoted, so the recipe gets the value the pipeline config holds."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    from mqa_rl.pipelines import override

    parser = OverridesParser.create()
    for value in (None, True, 3, 1.5, "runs/a-b.c:d@e+f", "a b", "it's", "100", "1e-4", "null", "~x%y", ["a", None, 2]):
        assert parser.parse_override(override("k", value)).value() == value, value
    assert override("baseline_from", None) == "baseline_from=null" and override("k", "runs/x") == "k=runs/x"

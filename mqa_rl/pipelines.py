"""Multi-step pipelines: recipes run one after another as a config of ``recipes/conf/pipeline/`` lists them
(``python recipes/pipeline.py pipeline=<name> [option=value ...]``).

A pipeline config holds its options (top-level keys, overridden on the command line like any Hydra key), ``checks``
(run before any step: a wrong option or a missing input is refused at once, nothing written) and ``steps``, in order.
A step is a line to print (``say``) and usually a recipe to run: ``run: <recipes/<run>.py>`` with ``args`` (Hydra
overrides: a string as it is, a list spliced in, a one-key mapping ``{key: value}`` written ``key=value`` with null as
``null``), ``multirun: true`` (Hydra's ``-m``), ``done`` (paths or globs: when each matches, the step is skipped, as
its output is there), ``when`` / ``unless`` (values: the step runs only when every ``when`` is set and no ``unless``
is), or ``parallel`` (such steps run at once, each skipped when done). ``for_each: <list>`` with ``steps`` repeats
those steps for every value, ``${each}`` naming it. Interpolations may use the resolvers below (``${pipe.sum:...}``).

Every step prints one line with the time since the pipeline started; a step that fails stops the pipeline with the
command that failed (the steps before it stay done: the same command again continues from there).
"""

from __future__ import annotations

import glob
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

STEP_KEYS = {"say", "run", "args", "multirun", "done", "when", "unless", "parallel"}
NOT_OPTIONS = ("checks", "steps", "derived")          # a pipeline config's keys that are not options


class PipelineRefused(ValueError):
    """A pipeline refused before any step ran: an unknown pipeline or option, a wrong value, a missing input."""


class StepFailed(RuntimeError):
    """A step's recipe exited with an error."""


# ----------------------------------------------------------------------------------------- resolvers
def _made_or_shipped(made: str, shipped: str, train) -> str:
    """The folder a step makes here (``made``) when it holds anything already, when ``train`` asks to make it, or when
    nothing ships at ``shipped``; else the shipped one."""
    return made if train or Path(made).exists() or not Path(shipped).exists() else shipped


def _run_value(folder: str, key: str):
    """A value of a run folder's config.yaml (e.g. the student's seed)."""
    path = Path(folder) / "config.yaml"
    if not path.is_file():
        raise PipelineRefused(f"{folder} has no config.yaml: it is no run folder of recipes/train_dqn.py")
    return OmegaConf.select(OmegaConf.load(path), key)


RESOLVERS = {
    "pipe.sum": lambda *xs: sum(int(x) for x in xs),
    "pipe.join": lambda xs, sep=",": sep.join(str(x) for x in xs),
    "pipe.eq": lambda a, b: str(a) == str(b),
    "pipe.made_or_shipped": _made_or_shipped,
    "pipe.run_value": _run_value,
}
for _name, _fn in RESOLVERS.items():
    if not OmegaConf.has_resolver(_name):
        OmegaConf.register_new_resolver(_name, _fn)


# ----------------------------------------------------------------------------------------- options
def pipelines(conf_dir: Path) -> list[str]:
    """The pipelines there are: recipes/conf/pipeline/<name>.yaml."""
    return sorted(p.stem for p in (Path(conf_dir) / "pipeline").glob("*.yaml"))


def options(conf_dir: Path, name: str) -> list[str]:
    """A pipeline's options: its config's top-level keys, less its checks and steps."""
    cfg = OmegaConf.load(Path(conf_dir) / "pipeline" / f"{name}.yaml")
    return [k for k in cfg if k not in NOT_OPTIONS and k != "defaults"]


def check_command_line(conf_dir: Path, argv: list[str]) -> None:
    """Refuse an unknown pipeline, or an option the chosen pipeline does not have, naming what there is (Hydra's own
    message for an unknown key would suggest adding it with +)."""
    given = {}
    for arg in argv:
        if arg.startswith("-") or "=" not in arg:
            continue                                       # flags (-m, --cfg job, ...) and their values
        key = arg.split("=", 1)[0]
        if key.startswith(("+", "~")) or key.startswith(("hydra.", "hydra/")) or key == "hydra":
            continue
        given[key.split(".")[0].split("@")[0]] = arg.split("=", 1)[1]
    name = given.pop("pipeline", None)
    if name is None:
        return                                             # Hydra says a pipeline must be chosen, listing them
    known = pipelines(conf_dir)
    if name not in known:
        raise PipelineRefused(f"pipeline={name}: no such pipeline; choose one of {', '.join(known)} "
                              f"(recipes/conf/pipeline/<name>.yaml)")
    have = options(conf_dir, name)
    unknown = [k for k in given if k not in have]
    if unknown:
        raise PipelineRefused(f"pipeline={name} has no option {', '.join(repr(k) for k in unknown)}: its options are "
                              f"{', '.join(have)} (recipes/conf/pipeline/{name}.yaml says what each does)")


# ----------------------------------------------------------------------------------------- checks
def _one_of(cfg, conf_dir, *, option: str, choices: list):
    value = OmegaConf.select(cfg, option)
    if value not in list(choices):
        raise PipelineRefused(f"{option}={value}: choose one of {', '.join(map(str, choices))}")


def _boolean(cfg, conf_dir, *, option: str):
    value = OmegaConf.select(cfg, option)
    if not isinstance(value, bool):
        raise PipelineRefused(f"{option} must be true or false, got '{value}'")


def _positive_int(cfg, conf_dir, *, option: str, optional: bool = False):
    value = OmegaConf.select(cfg, option)
    if optional and value is None:
        return
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise PipelineRefused(f"{option} must be a positive whole number{' or null' if optional else ''}, got '{value}'")


def _config_options(cfg, conf_dir, *, option: str, group: str):
    value = OmegaConf.select(cfg, option)
    values = list(value) if isinstance(value, (list, ListConfig)) else [value]
    known = sorted(p.stem for p in (Path(conf_dir) / group).glob("*.yaml"))
    if not values:
        raise PipelineRefused(f"{option}=[] names none: give one or more of {', '.join(known)}")
    for v in values:
        if v not in known:
            raise PipelineRefused(f"{option}: unknown {group} '{v}': choose among {', '.join(known)} "
                                  f"(recipes/conf/{group}/)")


def _finished_student(cfg, conf_dir, *, option: str):
    if OmegaConf.select(cfg, option) is None:
        raise PipelineRefused(f"give {option}=<the root of a finished `python recipes/pipeline.py pipeline=student`>")
    folder = Path(str(OmegaConf.select(cfg, option)))
    if not glob.glob(str(folder / "dqn" / "checkpoints" / "checkpoint-*")) or not (folder / "demos_1" / "demos.json").is_file():
        raise PipelineRefused(f"{option}={folder} holds no finished imitation student (dqn/checkpoints and demos_0,1): "
                              f"run `python recipes/pipeline.py pipeline=student root={folder} seed=<seed>` first")


def _same_teacher(cfg, conf_dir, *, folders: list, teacher: str):
    from mqa_rl.collectors.demonstrations import other_teachers_demonstrations
    from mqa_rl.modules.frozen_policies import privileged_options
    from mqa_rl.modules.systems import system_spec

    registry = OmegaConf.to_container(OmegaConf.load(Path(conf_dir) / "systems.yaml"))["systems"]
    oracle = privileged_options(system_spec(registry, f"{teacher}_teacher", kinds=("privileged",)))
    reason = other_teachers_demonstrations(folders, oracle, teacher)
    if reason:
        raise PipelineRefused(f"{reason}: choose another root=, set teacher= to match, or remove that folder")


CHECKS = {"one_of": _one_of, "boolean": _boolean, "positive_int": _positive_int, "config_options": _config_options,
          "finished_student": _finished_student, "same_teacher": _same_teacher}


def check(cfg: DictConfig, conf_dir: Path) -> None:
    """The pipeline's ``checks``, in order; the first that fails raises ``PipelineRefused``."""
    for i, node in enumerate(cfg.get("checks") or []):
        try:
            item = OmegaConf.to_container(node, resolve=True)
        except OmegaConfBaseException as error:
            raise PipelineRefused(f"checks[{i}]: {error}".split("\n")[0]) from error
        kind = item.pop("check", None)
        if kind not in CHECKS:
            raise PipelineRefused(f"checks[{i}]: unknown check {kind!r}; one of {', '.join(CHECKS)}")
        CHECKS[kind](cfg, conf_dir, **item)


# ----------------------------------------------------------------------------------------- steps
@dataclass
class Step:
    say: str
    run: str | None = None
    args: list[str] = field(default_factory=list)
    multirun: bool = False
    done: list[str] = field(default_factory=list)
    active: bool = True
    parallel: list["Step"] = field(default_factory=list)

    def command(self, recipes: Path, python: str = sys.executable) -> list[str]:
        return [python, str(Path(recipes) / f"{self.run}.py"), *(["-m"] if self.multirun else []), *self.args]

    def is_done(self) -> bool:
        return bool(self.done) and all(glob.glob(pattern) for pattern in self.done)


def override(key: str, value) -> str:
    """``key=value`` as Hydra reads it back: null, booleans, numbers and lists as such, a string quoted when needed."""
    return f"{key}={_value(value)}"


def _value(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_value(v) for v in value) + "]"
    text = str(value)
    plain = text and all(c.isalnum() or c in "_-+./:@" for c in text) and text.lower() not in ("null", "true", "false")
    try:
        float(text)                    # a string that reads as a number stays a string
    except ValueError:
        if plain:
            return text
    return "'" + text.replace("'", "\\'") + "'"


def _flat_args(args, where: str) -> list[str]:
    out = []
    for a in args or []:
        if isinstance(a, list):
            out += _flat_args(a, where)
        elif isinstance(a, dict):
            if len(a) != 1:
                raise PipelineRefused(f"{where}: an argument mapping holds one key=value, got {a}")
            (k, v), = a.items()
            out.append(override(k, v))
        elif a is not None:
            out.append(str(a))
    return out


def _as_list(value) -> list:
    return list(value) if isinstance(value, list) else [value]


def _step(item: dict, where: str, recipes: Path | None) -> Step:
    unknown = set(item) - STEP_KEYS
    if unknown or "say" not in item:
        raise PipelineRefused(f"{where}: a step has say (required), {', '.join(sorted(STEP_KEYS - {'say'}))}; "
                              f"got {sorted(item)}")
    active = all(_as_list(item.get("when", True))) and not any(_as_list(item.get("unless", False)))
    step = Step(say=str(item["say"]), run=item.get("run"), args=_flat_args(item.get("args"), where),
                multirun=bool(item.get("multirun", False)), done=[str(d) for d in _as_list(item.get("done") or [])],
                active=active)
    step.parallel = [_step({"say": step.say, **sub}, f"{where}.parallel[{j}]", recipes)
                     for j, sub in enumerate(item.get("parallel") or [])]
    for unit in step.parallel or [step]:
        if unit.run is not None and recipes is not None and not (Path(recipes) / f"{unit.run}.py").is_file():
            raise PipelineRefused(f"{where}: run: {unit.run} names no recipe (no {Path(recipes) / unit.run}.py)")
    return step


def plan(cfg: DictConfig, recipes: Path | None = None) -> list[Step]:
    """The pipeline's steps, resolved (``for_each`` expanded), in order; a step that does not resolve is refused."""
    try:
        return _plan(cfg, recipes)
    except OmegaConfBaseException as error:
        cause = error.__cause__ if isinstance(error.__cause__, PipelineRefused) else error
        raise PipelineRefused(f"{getattr(error, 'full_key', None) or 'a step'}: {cause}".split("\n")[0]) from error


def _plan(cfg: DictConfig, recipes: Path | None) -> list[Step]:
    root = OmegaConf.create(OmegaConf.to_container(cfg, resolve=False))
    OmegaConf.set_struct(root, False)
    steps = []
    for i, node in enumerate(root.get("steps") or []):
        if "for_each" in node:
            values = OmegaConf.select(root, f"steps.{i}.for_each")
            values = OmegaConf.to_container(values, resolve=True) if isinstance(values, ListConfig) else _as_list(values)
            for value in values:
                root["each"] = value
                for j in range(len(node.steps)):
                    item = OmegaConf.to_container(root.steps[i].steps[j], resolve=True)
                    steps.append(_step(item, f"steps[{i}].steps[{j}] ({value})", recipes))
            root.pop("each", None)
        else:
            steps.append(_step(OmegaConf.to_container(node, resolve=True), f"steps[{i}]", recipes))
    return steps


def elapsed(start: float) -> str:
    s = int(time.monotonic() - start)
    return f"{s // 60} min {s % 60} s"


def run_pipeline(cfg: DictConfig, recipes: Path, *, python: str = sys.executable, echo=print) -> list[dict]:
    """Check the pipeline ``cfg``, then run its steps in order (paths relative to the current directory), one line
    each with the time since the start; returns what became of every step. Raises ``PipelineRefused`` before any
    step when a check fails, ``StepFailed`` when a step's recipe fails (the steps after it are not run)."""
    recipes = Path(recipes)
    check(cfg, recipes / "conf")
    steps = plan(cfg, recipes)
    start, record = time.monotonic(), []

    def say(text: str) -> None:
        echo(f"=== [{elapsed(start)}] {text}")
        sys.stdout.flush()

    for step in steps:
        units = step.parallel or ([step] if step.run else [])
        if not step.active:
            say(f"{step.say}: not asked for, skipped")
            record.append({"say": step.say, "status": "off"})
            continue
        if not units:
            say(step.say)
            record.append({"say": step.say, "status": "said"})
            continue
        todo = [u for u in units if not u.is_done()]
        if not todo:
            say(f"{step.say}: done already ({', '.join(d for u in units for d in u.done)}), skipped")
            record.append({"say": step.say, "status": "done"})
            continue
        say(step.say)
        t0 = time.monotonic()
        running = [(u, subprocess.Popen(u.command(recipes, python))) for u in todo]
        try:
            codes = [(u, p.wait()) for u, p in running]
        finally:
            for _, p in running:
                if p.poll() is None:
                    p.terminate()
        failed = [(u, code) for u, code in codes if code != 0]
        if failed:
            unit, code = failed[0]
            raise StepFailed(f"step '{step.say}' failed after {elapsed(t0)} (exit code {code}): "
                             f"{' '.join(unit.command(recipes, 'python'))}\nWhat it printed above says why; fix that "
                             f"and run the same pipeline command again: the steps done are skipped or resumed.")
        record.append({"say": step.say, "status": "ran", "seconds": round(time.monotonic() - t0, 1)})
    return record

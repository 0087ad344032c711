"""The house's layering, read from the source (every import, also those inside functions): each package of
mqa_rl imports only from the layers below it, so no two packages import each other and the env never
imports the reward transforms, the policies or the learners built on it. Inside modules/ the same holds for
its parts: the push policy, the answering half and the stops, each in its own sub-package."""

import ast
from pathlib import Path
from conftest import REPO

PACKAGE = REPO / "mqa_rl"

# Bottom first. A package may import from a lower layer, never from its own layer's others or from above.
LAYERS = (
    ("keys", "files", "progress"),              # names, file formats, progress lines
    ("verified_checkpoint",),                   # checkpoints checked before they are read
    ("sim",),                                   # geometry, SAPIEN scene, pushers
    ("data",),                                  # objects, scenes, questions
    ("envs",),                                  # measure
    ("transforms",),                            # reward (and the env factory that composes them)
    ("modules",),                               # decide
    ("losses",),                                # learn
    ("collectors",),                            # gather (and the replay buffer)
    ("training", "evaluation"),                 # wire a training run; score episodes and answers
    ("demo",),
    ("pipelines",),                             # run recipes one after another (recipes/pipeline.py)
)
LAYER = {name: i for i, names in enumerate(LAYERS) for name in names}


def modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = ("mqa_rl", *path.relative_to(PACKAGE).with_suffix("").parts)
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def imports(name: str, path: Path, known: dict) -> set[str]:
    """The mqa_rl modules that ``name`` imports (``from pkg import mod`` counts as ``pkg.mod``)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
                base = ".".join(here[: len(here) - node.level + 1] + ([node.module] if node.module else []))
            found |= {f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names}
    return {m for m in found if m.split(".")[0] == "mqa_rl" and m != "mqa_rl" and m != name}


def graph() -> dict[str, set[str]]:
    known = modules()
    return {name: imports(name, path, known) for name, path in known.items()}


def package(module: str) -> str:
    return module.split(".")[1]


def test_every_package_is_placed_in_a_layer():
    unplaced = {package(m) for m in modules() if m != "mqa_rl"} - set(LAYER)
    assert not unplaced, f"place {sorted(unplaced)} in LAYERS (which packages may it import, which import it?)"


def test_packages_import_only_from_the_layers_below():
    upward = sorted(f"{m} imports {t}" for m, targets in graph().items() if m != "mqa_rl" for t in targets
                    if package(t) != package(m) and LAYER[package(t)] >= LAYER[package(m)])
    assert not upward, "\n".join(upward)


def test_no_module_imports_itself_through_others():
    g = graph()
    state: dict[str, int] = {}          # 1: on the current path, 2: done

    def visit(m: str, path: list[str]) -> None:
        state[m] = 1
        for t in sorted(g.get(m, ())):
            if state.get(t) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path[path.index(t):] + [t]))
            if t not in state:
                visit(t, path + [t])
        state[m] = 2

    for m in sorted(g):
        if m not in state:
            visit(m, [m])


# Inside modules: the push policy's network and policies, the answering half (which reads the push network's question
# encoder and its ImageNet backbone), the stops (which read both), then the builder of a system's policy from its spec
# and the registry of systems over it. The same rule one level down: each part imports only from the parts below it.
MODULE_PARTS = (
    ("push",),                                  # the Q-network, its trunks and heads, the policies that push
    ("answering",),                             # the VQA, the counting perception, the frame the answer reads
    ("stop",),                                  # when a policy stops
    ("frozen_policies",),                       # a system's policy from its spec
    ("systems",),                               # the systems by id
)
MODULE_PART = {name: i for i, names in enumerate(MODULE_PARTS) for name in names}


def part(module: str) -> str | None:
    """``push`` for ``mqa_rl.modules.push.push_qnet``; None for modules outside ``mqa_rl.modules`` or the package itself."""
    parts = module.split(".")
    return parts[2] if len(parts) > 2 and parts[1] == "modules" else None


def test_every_module_of_modules_is_placed_in_a_part():
    unplaced = {part(m) for m in modules() if part(m) is not None} - set(MODULE_PART)
    assert not unplaced, f"place {sorted(unplaced)} in MODULE_PARTS (a sub-package of modules/, or a file at its top)"


def test_the_parts_of_modules_import_only_from_the_parts_below():
    upward = sorted(f"{m} imports {t}" for m, targets in graph().items() if part(m) is not None for t in targets
                    if part(t) is not None and part(t) != part(m) and MODULE_PART[part(t)] >= MODULE_PART[part(m)])
    assert not upward, "\n".join(upward)

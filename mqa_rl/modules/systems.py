"""The MQA systems by id: how every recipe, the evaluation and the web demo look a system up in the one registry
(``recipes/conf/systems.yaml``, composed into each recipe's config as ``systems``), so that a system is defined once.

An entry is a ``frozen_policies`` spec — the manipulation policy, its stop (``stop_margin`` / ``stop_critic``) and the
frame it answers from (``kept_frame``) — plus keys that describe rather than build it (``table3: false``: a policy
reference, not a row of evaluate.py's default Table III). A system's VQA is the train_vqa.py run of the same id.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping

from omegaconf import DictConfig, OmegaConf

from mqa_rl.modules.frozen_policies import check_spec

DESCRIPTIVE = ("table3",)               # entry keys that are not part of the policy spec
REGISTRY = "recipes/conf/systems.yaml"


def _plain(systems) -> dict:
    return OmegaConf.to_container(systems, resolve=True) if isinstance(systems, DictConfig) else dict(systems)


def system_spec(systems: Mapping, name: str, kinds: Collection[str] | None = None) -> dict:
    """The checked policy spec of system ``name`` (without its descriptive keys). An unknown id names the known
    ones; with ``kinds``, a system of another kind names those of these kinds (what the caller can run)."""
    systems = _plain(systems)
    known = sorted(n for n, s in systems.items() if kinds is None or s.get("kind") in kinds)
    if name not in systems:
        raise ValueError(f"unknown system {name!r}; known: {', '.join(known)} (add one to {REGISTRY})")
    entry = dict(systems[name])
    if kinds is not None and entry.get("kind") not in kinds:
        raise ValueError(f"system {name!r} is of kind {entry.get('kind')!r}; this takes a system of kind "
                         f"{' | '.join(kinds)}: {', '.join(known)}")
    return check_spec({k: v for k, v in entry.items() if k not in DESCRIPTIVE})


def systems_by_id(systems: Mapping, names, kinds: Collection[str] | None = None) -> dict[str, dict]:
    """{id: checked spec} of the systems ``names`` (each as ``system_spec`` checks it)."""
    return {name: system_spec(systems, name, kinds) for name in names}


def table3_systems(systems: Mapping) -> list[str]:
    """The ids evaluate.py reports by default: every system but the policy references (``table3: false``)."""
    return [n for n, s in _plain(systems).items() if s.get("table3", True)]

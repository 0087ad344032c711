"""Resuming a run under a different config would mix two experiments in one checkpoint line silently
(e.g. a learning rate or reward changed between the killed run and ``resume=true``). The guard names
every setting that changed; lengthening a run, moving it to another device and where it logs are not
changes to the experiment."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable, Mapping

from omegaconf import OmegaConf

# settings a resume may change freely: how long, where it logs / evaluates / checkpoints, which device
RESUMABLE = ("resume", "resume_allow_changes", "out_dir", "threads", "device", "collector.total_frames",
             "demos.pretrain_updates", "demos.checkpoint_updates", "checkpoint.", "eval.", "logger.")


def flatten(config: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """{"a.b.c": value} for every leaf of a nested mapping (lists are leaves)."""
    out: dict[str, Any] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, f"{name}."))
        else:
            out[name] = value
    return out


def config_changes(old: Mapping[str, Any], new: Mapping[str, Any],
                   free: Iterable[str] = RESUMABLE) -> list[str]:
    """``"key: old -> new"`` for every setting that differs, except those under ``free`` (a name, or a
    prefix ending in '.'); a key present on one side only counts as changed."""
    free = tuple(free)
    a, b = flatten(old), flatten(new)

    def is_free(key: str) -> bool:
        return any(key == f or (f.endswith(".") and key.startswith(f)) for f in free)

    missing = object()
    return [f"{k}: {a.get(k, '(unset)')!r} -> {b.get(k, '(unset)')!r}"
            for k in sorted(set(a) | set(b))
            if not is_free(k) and a.get(k, missing) != b.get(k, missing)]


def refuse_changed_config(saved: Path, config: Mapping[str, Any], allow: bool = False,
                          free: Iterable[str] = RESUMABLE) -> list[str]:
    """Raise ``ValueError`` naming the changed settings when ``config`` differs from the run's ``saved``
    config.yaml (the settings of its newest checkpoint), unless ``allow`` (a deliberate new phase: say so
    with ``resume_allow_changes=true``); ``free``: the settings a resume may change. Returns the changes (printed when allowed); a run without a
    saved config (older than it) is not checked."""
    if not saved.exists():
        return []
    old = OmegaConf.to_container(OmegaConf.load(saved), resolve=True)
    only_saved, only_new = sorted(set(old) - set(config)), sorted(set(config) - set(old))
    if len(only_saved) >= 2 and len(only_new) >= 2:          # not a changed setting: another recipe's whole config
        raise ValueError(f"{saved.parent} holds another recipe's run (its config.yaml has the sections {only_saved}, "
                         f"this recipe's has {only_new} instead): choose another out_dir")
    changes = config_changes(old, config, free)
    if changes and not allow:
        raise ValueError(f"resume=true with settings that differ from the run in {saved.parent}:\n  "
                         + "\n  ".join(changes)
                         + "\nThe checkpoint was trained with the old values: resume with them, choose another "
                         "out_dir, or pass resume_allow_changes=true to continue deliberately under the new ones.")
    if changes:
        print("resume_allow_changes=true; continuing under changed settings:\n  " + "\n  ".join(changes))
    return changes

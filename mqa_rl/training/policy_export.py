"""A trained push policy as a small run folder that ships: ``config.yaml``, one checkpoint holding only
the Q-network (and the SHA-256 of its files), the training logs (``csv/``) and ``provenance.json``.

A ``train_dqn.py`` checkpoint carries the replay buffer (1.5 GB at the default config) beside ~1 MB of
weights; what a user needs to evaluate or roll out the policy is the weights and the config that builds
the network. The exported folder is a run folder like any other (``load_greedy``, ``evaluate_policy.py
run=...``, the answering systems' ``run``), written to a hidden folder and renamed into place.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from torchrl.checkpoint import Checkpoint, CheckpointRotation

from mqa_rl.verified_checkpoint import INTEGRITY, IntegrityAdapter


EXPORT_FILES = {"config.yaml", "checkpoints", "csv", "provenance.json"}


def is_export(folder: Path) -> bool:
    """Whether ``folder`` holds an earlier export and nothing else: its provenance names a source run."""
    try:
        provenance = json.loads((folder / "provenance.json").read_text())
    except (OSError, ValueError):
        return False
    names = {p.name for p in folder.iterdir()}
    return isinstance(provenance, dict) and "source_run" in provenance and names <= EXPORT_FILES


def has_dashboards(run) -> bool:
    """Whether ``run`` is a train_dqn.py run whose dashboards an evaluation logs into: not an exported policy (e.g. the
    shipped checkpoints/dqn_*, which an evaluation only reads: its provenance names the run it came from)."""
    if not run or not (Path(run) / "checkpoints").is_dir():
        return False
    try:
        provenance = json.loads((Path(run) / "provenance.json").read_text())
    except (OSError, ValueError):
        return True
    return not (isinstance(provenance, dict) and "source_run" in provenance)


def check_export_target(run: Path, out_dir: Path, overwrite: bool) -> None:
    """``overwrite`` may replace an earlier export only: never the run itself, a folder holding the run, or
    a folder with anything an export does not write (a user's files, another run's checkpoints)."""
    source, target = run.resolve(), out_dir.resolve()
    if target != source and source in target.parents:
        raise ValueError(f"out_dir={out_dir} lies inside the run being exported ({run}): a folder there (e.g. under "
                         f"checkpoints/) would break its resume; choose a folder outside it, e.g. checkpoints/<name>")
    if not out_dir.exists():
        return
    if not overwrite:
        raise FileExistsError(f"{out_dir} exists: choose another out_dir, or overwrite=true to replace an earlier export")
    if source == target or target in source.parents:
        raise ValueError(f"out_dir={out_dir} holds the run being exported ({run}): choose another out_dir")
    if not out_dir.is_dir() or not is_export(out_dir):
        raise FileExistsError(f"{out_dir} is not an earlier export (it has no export provenance, or holds other files): "
                              f"overwrite=true replaces only an export; choose another out_dir")


def export_policy(actor, run: str | Path, out_dir: str | Path, *, step: int, provenance: dict,
                  overwrite: bool = False) -> Path:
    """Write ``actor``'s weights with ``run``'s config.yaml to ``out_dir`` (atomically); returns it."""
    run, out_dir = Path(run), Path(out_dir)
    check_export_target(run, out_dir, overwrite)
    staging = out_dir.with_name(f".{out_dir.name}.tmp{os.getpid()}")
    shutil.rmtree(staging, ignore_errors=True)
    try:
        staging.mkdir(parents=True)
        shutil.copy2(run / "config.yaml", staging / "config.yaml")
        if (run / "csv").is_dir():              # the training curves (Fig. 7 reads them), ~0.2 MB
            shutil.copytree(run / "csv", staging / "csv")
        checkpoint = Checkpoint(policy=actor)
        checkpoint.register(INTEGRITY, {}, adapter=IntegrityAdapter())
        CheckpointRotation(staging / "checkpoints", keep_last=1).save(checkpoint, step=int(step))
        (staging / "provenance.json").write_text(json.dumps(provenance, indent=1) + "\n")
        if out_dir.exists():
            old = out_dir.with_name(f".{out_dir.name}.old{os.getpid()}")
            os.replace(out_dir, old)
            os.replace(staging, out_dir)
            shutil.rmtree(old)
        else:
            os.replace(staging, out_dir)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out_dir


def folder_bytes(folder: Path) -> int:
    return sum(p.stat().st_size for p in Path(folder).rglob("*") if p.is_file())

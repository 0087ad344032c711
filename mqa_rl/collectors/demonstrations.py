"""Demonstrations for the push Q-network: what a teacher that reads the simulator does in each state it meets.

The teacher (``PrivilegedPushPolicy``; the students' is the image teacher, ``order="visible_first",
geometry="visible"``) finds a partly visible target, the object standing on it, and a push that moves that
object away. A policy acting from rgb, depth and the question can learn that from the images (the occluder
borders the visible part of the target, higher in depth), and the demonstrations say it with one labelled
action per state rather than with a few noisy rewards per episode. They feed a loss beside DQN
(``mqa_rl.losses.demonstration``, as DQfD, Hester et al. 2018). States are stored as the replay stores them.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections import Counter
from pathlib import Path

import torch
from tensordict import TensorDict

from mqa_rl import keys
from mqa_rl.collectors.replay import OBS_KEYS
from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.envs import actions
from mqa_rl.files import load_memmap
from mqa_rl.modules.push.privileged_policy import PrivilegedPushPolicy
from mqa_rl.progress import Progress

DEMO_KEYS = (*OBS_KEYS, keys.TARGET_CELLS, keys.ACTION)
DEMOS_META = "demos.json"            # beside the memmap folder "data": written last (recipes/collect.py what=demonstrations)
# the teacher's options a demonstration set records that tell its teachers apart, with the value an older set lacking one ran with
TEACHER_OPTIONS = {"refine_radius": 0, "min_visible_fraction": 0.3, "require_gain": False, "geometry": "visible",
                   "order": "visible_first"}


def collect_demonstrations(env, states: int, *, progress: bool = True, **oracle_options) -> TensorDict:
    """[states] oracle steps (observation, oracle action) on ``env`` (a ``SapienBinEnv``): episodes from
    reset until the episode ends, every step kept, the stops included."""
    if states < 1:
        raise ValueError(f"need states ≥ 1, got {states}")
    oracle = PrivilegedPushPolicy(env, **oracle_options)
    out = []
    bar = Progress(states, "demonstrations", unit="state", disable=not progress)
    while len(out) < states:
        td = env.reset()
        while len(out) < states:
            td = oracle(td)
            step = td.select(*DEMO_KEYS).clone()
            for key in (keys.DEPTH, keys.TARGET_CELLS):
                step.set(key, step.get(key).to(torch.float16))
            out.append(step)
            bar.update(1)
            td = env.step(td)
            if td["next", "done"].item():
                break
            td = td["next"]
    bar.close()
    return torch.stack(out)


def write_demonstration_set(out_dir, env, states: int, oracle: dict, settings: dict, *, progress: bool = True) -> dict:
    """``states`` demonstrations of the teacher ``oracle`` (its options) on ``env`` as a folder: ``out_dir/data`` (a
    memmap TensorDict) and ``out_dir/demos.json`` (``settings``, the teacher's options, the dataset's fingerprint,
    action statistics), both renamed into place at the end: a killed run leaves nothing half-written. Returns the meta."""
    out = Path(out_dir)
    if (out / DEMOS_META).exists():
        raise FileExistsError(f"{out} already holds demonstrations: choose another out_dir or delete it")
    t0 = time.perf_counter()
    demos = collect_demonstrations(env, states, progress=progress, **oracle)
    seconds = time.perf_counter() - t0
    act = demos.get(keys.ACTION)
    allowed = demos.get(keys.ACTION_MASK).gather(-1, act[:, None]).squeeze(-1)
    meta = {**settings, "oracle": oracle, "dataset_sha256": dataset_fingerprint(env.dataset.root),
            "seconds": round(seconds, 1), "stop_fraction": float((act == actions.STOP).float().mean()),
            "masked_fraction": float((~allowed).float().mean()),
            "directions": dict(Counter((act[act != actions.STOP] // (actions.GRID ** 2)).tolist()))}
    tmp = out.with_name(f".{out.name}.tmp{os.getpid()}")
    if tmp.exists():
        shutil.rmtree(tmp)
    demos.memmap(tmp / "data")
    (tmp / DEMOS_META).write_text(json.dumps(meta, indent=1))
    if out.exists():                       # an empty or unfinished folder (no demos.json)
        shutil.rmtree(out)
    os.replace(tmp, out)
    print(f"{len(demos)} demonstrations in {seconds:.0f} s -> {out}: stop {meta['stop_fraction']:.2f}, "
          f"masked {meta['masked_fraction']:.3f}")
    return meta


def other_teachers_demonstrations(folders, oracle: dict, teacher: str) -> str | None:
    """Why one of ``folders`` holds demonstrations of another teacher than ``oracle`` (the options of the teacher
    named ``teacher``), or None when each holds none or the same teacher's: reusing them would train a student on
    the other teacher silently."""
    want = _described(oracle)
    for folder in map(Path, folders):
        if (folder / DEMOS_META).is_file():
            have = _described(json.loads((folder / DEMOS_META).read_text()).get("oracle", {}))
            if have != want:
                return (f"{folder} holds demonstrations of another teacher (oracle {', '.join(TEACHER_OPTIONS)} = "
                        f"{have}), not the {teacher} teacher's ({want})")
    return None


def _described(oracle: dict) -> str:
    o = {**TEACHER_OPTIONS, **{k: v for k, v in oracle.items() if k in TEACHER_OPTIONS}}
    return (f"{o['refine_radius']} {float(o['min_visible_fraction'])} {str(o['require_gain']).lower()} {o['geometry']} "
            f"{o['order']}")


def load_demonstrations(path, dataset_root: str | Path | None = None) -> TensorDict:
    """The demonstrations in memory; clear errors for a missing, unfinished or other-dataset folder.
    A list of folders is concatenated (the students' two collection processes)."""
    if not isinstance(path, (str, Path)):                     # a list (or hydra ListConfig) of folders
        parts = [load_demonstrations(p, dataset_root) for p in path]
        if not parts:
            raise ValueError("demos.path is an empty list: give one or more demonstration folders")
        return torch.cat([p.select(*DEMO_KEYS) for p in parts])
    path = Path(path)
    hint = "collect them with `python recipes/collect.py what=demonstrations` (or set demos.path=null)"
    if not (path / DEMOS_META).exists():
        raise FileNotFoundError(f"no demonstrations in {path} ({DEMOS_META} missing): {hint}")
    meta = json.loads((path / DEMOS_META).read_text())
    if dataset_root is not None and meta.get("dataset_sha256") != dataset_fingerprint(dataset_root):
        raise ValueError(f"the demonstrations in {path} were collected on another dataset than {dataset_root}: {hint}")
    try:
        demos = load_memmap(path / "data", what="the demonstrations", hint=hint).clone()
    except Exception as error:
        raise ValueError(f"cannot read the demonstrations in {path} ({type(error).__name__}: {error}): {hint}") from error
    missing = [k for k in DEMO_KEYS if k not in demos.keys(True)]
    if missing:
        raise ValueError(f"{path} lacks {missing}: {hint}")
    return demos

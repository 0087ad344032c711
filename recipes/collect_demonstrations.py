"""Collect a teacher's demonstrations on the train split, for the students (train_dqn.py demos.path=).

    python recipes/collect_demonstrations.py                     # the image teacher, 600 states -> runs/demos
    python recipes/collect_demonstrations.py teacher=refined_teacher out_dir=runs/demos_refined   # the refined teacher
    python recipes/train_dqn.py profile=student demos.path=runs/demos ...

The teacher, a privileged system of recipes/conf/systems.yaml (``teacher=``, its options overridable one by one:
``oracle.<option>=``), reads the simulator (which target is partly visible, which object stands on it); the states it
meets and its actions are stored as the replay stores observations (``mqa_rl.collectors.demonstrations``).
Writes ``out_dir/data`` (a memmap TensorDict) and ``out_dir/demos.json`` (settings, dataset
fingerprint, action statistics), both renamed into place at the end: a killed run leaves nothing
half-written.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections import Counter
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from mqa_rl import keys
from mqa_rl.collectors.demonstrations import DEMOS_META, collect_demonstrations
from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.envs import actions
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.modules.frozen_policies import privileged_options
from mqa_rl.modules.systems import system_spec


def teacher_options(cfg: DictConfig) -> dict:
    """Every option of the teacher the demonstrations are collected with: the system ``teacher``'s, each overridden
    by a non-null ``oracle.<option>``."""
    spec = system_spec(cfg.systems, cfg.teacher, kinds=("privileged",))
    return privileged_options({**spec, **{k: v for k, v in OmegaConf.to_container(cfg.oracle).items() if v is not None}})


def collect(cfg: DictConfig) -> dict:
    out = Path(cfg.out_dir)
    if (out / DEMOS_META).exists():
        raise FileExistsError(f"{out} already holds demonstrations: choose another out_dir or delete it")
    if not Path(cfg.dataset).exists():
        raise FileNotFoundError(f"dataset {cfg.dataset} does not exist: make it with recipes/make_dataset.py")
    oracle = teacher_options(cfg)                     # a bad teacher refused before the simulator starts
    torch.manual_seed(cfg.seed)
    env = SapienBinEnv(cfg.dataset, seed=cfg.seed, **OmegaConf.to_container(cfg.env))
    t0 = time.perf_counter()
    demos = collect_demonstrations(env, cfg.states, progress=cfg.progress, **oracle)
    seconds = time.perf_counter() - t0
    act = demos.get(keys.ACTION)
    allowed = demos.get(keys.ACTION_MASK).gather(-1, act[:, None]).squeeze(-1)
    settings = {k: v for k, v in OmegaConf.to_container(cfg, resolve=True).items() if k != "systems"}
    meta = {**settings, "oracle": oracle, "dataset_sha256": dataset_fingerprint(cfg.dataset),
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


@hydra.main(config_path="conf", config_name="collect_demonstrations", version_base="1.3")
def main(cfg: DictConfig) -> None:
    collect(cfg)


if __name__ == "__main__":
    main()

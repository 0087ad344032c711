"""Helpers for the web demo's tests: a runs folder with a real (untrained) Q-network run, a corrupt
copy and a stray weights file, and the demo served in-process on a free port of 127.0.0.1."""

from __future__ import annotations

import shutil
import socket
from pathlib import Path

import torch
from omegaconf import OmegaConf

ROOT = Path(__file__).resolve().parents[1]
REWARD = OmegaConf.to_container(OmegaConf.load(ROOT / "recipes" / "conf" / "reward" / "global_local.yaml"))
TRUNK = OmegaConf.to_container(OmegaConf.load(ROOT / "recipes" / "conf" / "trunk" / "light.yaml"))


def write_untrained_run(run: Path, dataset_dir: Path) -> Path:
    """A recipes/train_dqn.py-shaped run folder (config.yaml + one checkpoint with the integrity
    record) holding a freshly initialised light Q-network: what load_greedy reads, without training."""
    from torchrl.checkpoint import Checkpoint, CheckpointRotation

    from mqa_rl import keys
    from mqa_rl.envs.sapien_bin import SapienBinEnv
    from mqa_rl.modules.push.push_policy import make_push_qnet, make_q_actor
    from mqa_rl.verified_checkpoint import INTEGRITY, IntegrityAdapter

    run.mkdir(parents=True)
    cfg = {"reward": REWARD, "model": TRUNK, "action_mask": True, "dataset": str(dataset_dir),
           "env": {"split": "train", "max_pushes": 10, "image_size": 224}}
    OmegaConf.save(OmegaConf.create(cfg), run / "config.yaml")
    env = SapienBinEnv(dataset_dir, split=None)
    torch.manual_seed(0)
    net = make_push_qnet(TRUNK, vocab_size=env.observation_spec[keys.QUESTION].space.n,
                         camera_distance=env.camera.distance)
    actor = make_q_actor(net, env.action_spec, masked=True)
    ckpt = Checkpoint(policy=actor)
    ckpt.register(INTEGRITY, {}, adapter=IntegrityAdapter())
    return CheckpointRotation(run / "checkpoints", keep_last=1).save(ckpt, step=16)


def make_runs_folder(root: Path, dataset_dir: Path) -> Path:
    """``root/runs`` with ``good`` (usable), ``corrupt`` (a weight file truncated) and ``model.pt`` (junk)."""
    runs = root / "runs"
    checkpoint = write_untrained_run(runs / "good", dataset_dir)
    shutil.copytree(runs / "good", runs / "corrupt")
    tensors = sorted((runs / "corrupt" / "checkpoints" / checkpoint.name / "components").glob("*-policy/**/*.memmap"))
    biggest = max(tensors, key=lambda f: f.stat().st_size)
    biggest.write_bytes(biggest.read_bytes()[: biggest.stat().st_size // 2])
    (runs / "model.pt").write_bytes(b"not a checkpoint")
    return runs


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def offered_systems() -> dict:
    """The systems recipes/demo.py offers by default (demo.yaml's ``offered``, from recipes/conf/systems.yaml)."""
    from mqa_rl.modules.systems import systems_by_id

    conf = ROOT / "recipes" / "conf"
    return systems_by_id(OmegaConf.load(conf / "systems.yaml").systems, OmegaConf.load(conf / "demo.yaml").offered)


def start_demo(dataset_dir: Path, runs: Path | None, cache_dir: Path, **cfg):
    """(backend, blocks, url): the demo served on 127.0.0.1 by this process (close with ``stop_demo``), offering
    the systems recipes/demo.py offers."""
    from mqa_rl.demo.app import launch
    from mqa_rl.demo.backend import DemoBackend, DemoConfig

    cfg.setdefault("systems", offered_systems())
    backend = DemoBackend(DemoConfig(dataset=dataset_dir, reward=REWARD, runs=runs, cache_dir=cache_dir, **cfg))
    port = free_port()
    demo = launch(backend, host="127.0.0.1", port=port, block=False, quiet=True)
    return backend, demo, f"http://127.0.0.1:{port}/"


def stop_demo(backend, demo) -> None:
    demo.close()
    backend.close()

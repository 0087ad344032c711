"""Export a trained push policy, or a part of it, as a small folder that ships; ``export=`` says what.

    python recipes/export_policy.py run=runs/global out_dir=checkpoints/dqn_global \
        trained_with="python recipes/train_dqn.py reward=global out_dir=runs/global"
    python recipes/export_policy.py export=recognition run=checkpoints/dqn_geometric_student out_dir=runs/recognition

``export=policy`` (the default): a run folder (config.yaml + the Q-network's weights, ~1 MB) without the replay buffer
its training checkpoints carry (1.5 GB at the default config). It loads wherever a run folder does
(``python recipes/evaluate_policy.py run=checkpoints/dqn_global``, or as an answering system:
``systems.dqn_global.run=checkpoints/dqn_global``), and is checked after writing: the exported network gives the
source's Q values, bit for bit, on a test observation.

``export=recognition``: the policy's recognition (rgb trunk, class head, question encoder and its class attention) as
``out_dir/recognition.pt``, the file ``recipes/pretrain.py part=push_trunk`` writes. A policy trained with
``model.pretrained=`` (frozen) carries the pretraining's visual weights unchanged, so a new run can start from them
without the ~16 minutes of pretraining (``train_dqn.py model.pretrained=<out_dir>/recognition.pt``). The question
part is the policy's (trained further beside it); the file's meta says where it came from.
"""

from __future__ import annotations

import datetime
import json
import subprocess
from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig
from torchrl.checkpoint import Checkpoint

from mqa_rl import keys
from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.modules.push.pretrained_recognition import save_recognition
from mqa_rl.modules.push.push_qnet import PushQNet
from mqa_rl.modules.push.trained_policy import load_greedy, read_run_config
from mqa_rl.training.policy_export import check_export_target, export_policy, folder_bytes
from mqa_rl.transforms.mqa_env import make_mqa_env


def _git_commit() -> str | None:
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10,
                             cwd=Path(__file__).parent)
        return out.stdout.strip() or None
    except OSError:
        return None


EXPORTS = ("policy", "recognition")
RECOGNITION_FILE = "recognition.pt"


def export(cfg: DictConfig):
    """What ``cfg.export`` names, exported from ``cfg.run`` into ``cfg.out_dir``."""
    if cfg.export not in EXPORTS:
        raise ValueError(f"export={cfg.export}: one of {', '.join(EXPORTS)} (the policy as a small run folder, or its "
                         f"recognition as a file)")
    if not cfg.run or not cfg.out_dir:
        raise ValueError("give run=<a train_dqn.py output folder or exported policy> and out_dir=<where the export goes>")
    return export_policy_folder(cfg) if cfg.export == "policy" else export_recognition(cfg)


def export_recognition(cfg: DictConfig) -> Path:
    run, out = Path(cfg.run), Path(cfg.out_dir) / RECOGNITION_FILE
    if out.exists() and not cfg.overwrite:
        raise FileExistsError(f"{out} exists: choose another out_dir, or overwrite=true to replace it")
    run_cfg = read_run_config(run)
    if not run_cfg.model.get("class_map"):
        raise ValueError(f"{run} was trained without model.class_map: it has no recognition to export")
    dataset = str(cfg.dataset or run_cfg.dataset)
    env = make_mqa_env(dataset, split="test", seed=0, image_size=int(run_cfg.env.image_size))
    try:
        actor, _, source = load_greedy(run, cfg.checkpoint, env)
        classes = env.dataset.classes
    finally:
        env.close()
    net = next(m for m in actor.modules() if isinstance(m, PushQNet))
    meta = {"extracted_from": str(source), "dataset_sha256": dataset_fingerprint(dataset),
            "pretrained": run_cfg.model.get("pretrained"), "pretrained_frozen": run_cfg.model.get("pretrained_frozen"),
            "extracted": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
    save_recognition(net, out, classes, meta)
    print("recognition:", json.dumps({"out": str(out), **meta}))
    return out


def export_policy_folder(cfg: DictConfig) -> dict:
    run = Path(cfg.run)
    run_cfg = read_run_config(run)
    source_run = json.loads((run / "provenance.json").read_text()).get("source_run") \
        if (run / "provenance.json").is_file() else None
    if source_run:
        raise ValueError(f"{run} is already an export of {source_run} (its checkpoint holds only the Q-network): use it "
                         f"as it is (copy the folder), or export the training run itself")
    check_export_target(run, Path(cfg.out_dir), bool(cfg.overwrite))      # before the env is built
    dataset = str(cfg.dataset or run_cfg.dataset)
    env = make_mqa_env(dataset, split="test", seed=0, image_size=int(run_cfg.env.image_size))
    try:
        actor, _, source = load_greedy(run, cfg.checkpoint, env)
        trained: dict = {}
        Checkpoint(trainer_state=trained).load(source, components=["trainer_state"])
        step = int(trained["frames"])
        provenance = {"source_run": str(run), "source_checkpoint": f"checkpoints/{source.name}",
                      **{k: trained[k] for k in ("frames", "updates", "episodes", "train_seconds", "demo_pretrain_updates",
                                                  "demo_pretrain_seconds") if k in trained},
                      "reward": run_cfg.reward.name, "trunk": run_cfg.model.trunk,
                      "dataset": dataset, "dataset_sha256": dataset_fingerprint(dataset),
                      "trained_with": cfg.trained_with, "git_commit": _git_commit(),
                      "exported": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
        out = export_policy(actor, run, cfg.out_dir, step=step, provenance=provenance, overwrite=cfg.overwrite)
        exported, _, _ = load_greedy(out, None, env)
        td = env.reset()
        with torch.no_grad():
            same = torch.equal(actor(td.clone())[keys.ACTION_VALUE], exported(td.clone())[keys.ACTION_VALUE])
    finally:
        env.close()
    if not same:
        raise RuntimeError(f"the export in {out} does not reproduce {source}'s Q values: delete it and report a bug")
    summary = {"out_dir": str(out), "bytes": folder_bytes(out), "source": str(source), "frames": step}
    print("exported:", json.dumps(summary))
    return summary


@hydra.main(config_path="conf", config_name="export_policy", version_base="1.3")
def main(cfg: DictConfig) -> None:
    export(cfg)


if __name__ == "__main__":
    main()

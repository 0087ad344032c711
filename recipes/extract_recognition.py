"""Write a trained push policy's recognition (rgb trunk, class head, question encoder and its class
attention) as a recognition file, the format ``recipes/pretrain.py part=push_trunk`` writes.

    python recipes/extract_recognition.py run=checkpoints/dqn_geometric_student out=runs/recognition/recognition.pt

Why: a policy trained with ``model.pretrained=`` (frozen) carries the pretraining's visual weights
unchanged, so a new run can start from them without the ~16 minutes of pretraining. The question part
is the policy's (trained further beside it); the file's meta says where it came from.
"""

from __future__ import annotations

import datetime
import json
from pathlib import Path

import hydra
from omegaconf import DictConfig

from mqa_rl.data.dataset import dataset_fingerprint
from mqa_rl.modules.pretrained_recognition import save_recognition
from mqa_rl.modules.push_qnet import PushQNet
from mqa_rl.modules.trained_policy import load_greedy, read_run_config
from mqa_rl.transforms.mqa_env import make_mqa_env


def extract(cfg: DictConfig) -> Path:
    if not cfg.run or not cfg.out:
        raise ValueError("give run=<a train_dqn.py run or exported policy folder> and out=<recognition file to write>")
    run, out = Path(cfg.run), Path(cfg.out)
    if out.exists() and not cfg.overwrite:
        raise FileExistsError(f"{out} exists: choose another out, or overwrite=true to replace it")
    run_cfg = read_run_config(run)
    if not run_cfg.model.get("class_map"):
        raise ValueError(f"{run} was trained without model.class_map: it has no recognition to extract")
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


@hydra.main(config_path="conf", config_name="extract_recognition", version_base="1.3")
def main(cfg: DictConfig) -> None:
    extract(cfg)


if __name__ == "__main__":
    main()

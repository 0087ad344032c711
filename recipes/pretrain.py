"""Pretrain a part of a model before the training that starts from it; ``part=`` says which
(recipes/conf/part/<part>.yaml):

    python recipes/pretrain.py part=push_trunk          # the push Q-network's recognition (~16 min on 2 cores)
    python recipes/pretrain.py part=push_trunk frames.count=300 train.steps=50 out_dir=runs/tiny
    python recipes/collect.py what=rollouts system=random splits=[train]     # the VQA encoder's frames come from these
    python recipes/pretrain.py part=vqa_encoder         # the VQA's image encoder (EQA's CNN), ~28 min on 2 cores
    python recipes/pretrain.py part=vqa_encoder resume=true                  # continue a killed run
    python recipes/pretrain.py part=vqa_encoder export_pack=runs/frames.xz   # the frames in one file (~21 kB each) ...
    python recipes/pretrain.py part=vqa_encoder frames.pack=runs/frames.xz device=cuda   # ... to train on a GPU machine

- ``push_trunk``: the rgb trunk and a per-cell class head learn the class fractions of every action-grid cell from the
  simulator's segmentation, then the question encoder learns which class a question asks about; writes
  ``out_dir/recognition.pt`` (runs/recognition), what ``train_dqn.py model.class_map=true model.pretrained=`` starts
  from (``mqa_rl.training.push_trunk_pretraining``).
- ``vqa_encoder``: EQA's CNN reconstructs the image, labels every pixel with its class and predicts its height, from
  the rollouts' frames; writes ``out_dir/encoder.pt`` (``${root}/encoder``), what ``train_vqa.py`` loads
  (``mqa_rl.training.vqa_encoder_pretraining``).

Both log through the logger group as train_dqn.py does (TensorBoard by default; logger=mlflow | wandb | csv).
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import hydra
from omegaconf import DictConfig

from mqa_rl.training.push_trunk_pretraining import pretrain_push_trunk
from mqa_rl.training.signals import exit_on_sigterm
from mqa_rl.training.vqa_encoder_pretraining import export_pack, pretrain_vqa_encoder

PARTS = {"push_trunk": pretrain_push_trunk, "vqa_encoder": pretrain_vqa_encoder}


def pretrain(cfg: DictConfig):
    """The part ``cfg.part`` pretrained as its config says (``export_pack=``: the VQA encoder's frames written instead)."""
    if cfg.get("export_pack"):
        return export_pack(cfg)
    return PARTS[cfg.part](cfg)


@hydra.main(config_path="conf", config_name="pretrain", version_base="1.3")
def main(cfg: DictConfig) -> None:
    exit_on_sigterm()
    pretrain(cfg)


if __name__ == "__main__":
    main()

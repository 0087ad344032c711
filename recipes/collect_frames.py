"""Render labelled frames of a pretraining-only dataset of fresh piles for the counting perception.

    python recipes/make_dataset.py dataset.out_dir=data/mqa_frames dataset.seed=101 'dataset.num_scenes={easy:100,medium:100,hard:100}'
    python recipes/collect_frames.py                       # resumable: run it again to finish
    python recipes/train_perception.py

Refuses a pretraining dataset that shares a scene with a protected split (``protected``: the answering
test split, held-out piles). See ``mqa_rl.collectors.perception_frames`` for what a frame holds.
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

import hydra
from omegaconf import DictConfig

from mqa_rl.collectors.perception_frames import collect_perception_frames
from mqa_rl.data import MQADataset
from mqa_rl.training.signals import exit_on_sigterm


@hydra.main(config_path="conf", config_name="collect_frames", version_base="1.3")
def main(cfg: DictConfig) -> None:
    exit_on_sigterm()
    protected = [(MQADataset(p.dataset), p.split) for p in cfg.protected]
    summary = collect_perception_frames(cfg.out_dir, cfg.dataset, episodes_per_scene=int(cfg.episodes_per_scene),
                                        pushes=int(cfg.pushes), size=int(cfg.size), render=int(cfg.render),
                                        protected=protected,
                                        workers=int(cfg.workers), chunk_episodes=int(cfg.chunk_episodes),
                                        seed=int(cfg.seed), overwrite=bool(cfg.overwrite))
    print("done:", summary)


if __name__ == "__main__":
    main()

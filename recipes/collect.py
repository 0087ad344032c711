"""Collect what the learners and the evaluation read; ``what=`` says which (recipes/conf/what/<kind>.yaml):

    python recipes/collect.py what=rollouts system=random          # a system's rollouts for its VQA: train + test
    python recipes/collect.py what=rollouts system=dqn_local       # greedy DQN(R_l) from runs/local
    python recipes/collect.py what=rollouts system=privileged splits=[test] questions=all_types
    python recipes/collect.py what=rollouts system=random collection.backend=ray collection.workers=8 ray.address=auto
    python recipes/collect.py what=frames                          # labelled frames for the counting perception
    python recipes/collect.py what=demonstrations teacher=refined_teacher out_dir=runs/demos_refined
    python recipes/collect.py what=episodes episodes=3 'env.difficulties=[hard]' video_format=gif

- ``rollouts``: one MQA system's frozen policy (recipes/conf/systems.yaml) over the questions, stored per split in
  ``${root}/rollouts/<questions>/<system>/<split>`` (an ``EpisodeStore``, ``mqa_rl.collectors.rollouts``). The answer
  camera follows the VQA the rollouts are for (``vqa=counting``, the default: 448 px; ``vqa=eqa``: none).
- ``frames``: renders of a pretraining-only dataset of fresh piles, labelled from the simulator
  (``mqa_rl.collectors.perception_frames``); a dataset sharing a scene with a ``protected`` split is refused.
- ``demonstrations``: a teacher (a privileged system; ``oracle.<option>=`` overrides its options one by one) on the
  train split, the states it meets and its pushes as the replay stores them, for ``train_dqn.py demos.path=``
  (``mqa_rl.collectors.demonstrations``); written at the end, a killed run leaves nothing half-written.
- ``episodes``: a few episodes of the random baseline, a video each and a log of what every push changed
  (``mqa_rl.collectors.episode_log``).

Rollouts and frames are resumable: run the same command again and only what is missing is collected.
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

from pathlib import Path

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from mqa_rl.collectors.demonstrations import write_demonstration_set
from mqa_rl.collectors.episode_log import random_episodes
from mqa_rl.collectors.perception_frames import collect_perception_frames
from mqa_rl.collectors.rollouts import collect_split
from mqa_rl.data import MQADataset
from mqa_rl.envs.sapien_bin import SapienBinEnv
from mqa_rl.modules.frozen_policies import privileged_options
from mqa_rl.modules.systems import system_spec
from mqa_rl.training.signals import exit_on_sigterm


def need_dataset(cfg: DictConfig) -> None:
    if not Path(cfg.dataset).exists():
        raise FileNotFoundError(f"dataset {cfg.dataset} does not exist: make it with recipes/make_dataset.py")


def rollouts(cfg: DictConfig) -> list[dict]:
    spec = system_spec(cfg.systems, cfg.system)
    need_dataset(cfg)
    summaries = []
    for split in cfg.splits:
        summary = collect_split(Path(cfg.out_dir) / split, split, dataset=cfg.dataset, policy=spec,
                                questions=OmegaConf.to_container(cfg.questions),
                                collection=OmegaConf.to_container(cfg.collection, resolve=True), overwrite=cfg.overwrite,
                                progress=cfg.progress, ray_address=cfg.ray.address)
        print(f"{cfg.system} {split}: {summary}", flush=True)
        summaries.append(summary)
    return summaries


def frames(cfg: DictConfig) -> dict:
    protected = [(MQADataset(p.dataset), p.split) for p in cfg.protected]
    summary = collect_perception_frames(cfg.out_dir, cfg.dataset, episodes_per_scene=int(cfg.episodes_per_scene),
                                        pushes=int(cfg.pushes), size=int(cfg.size), render=int(cfg.render),
                                        protected=protected,
                                        workers=int(cfg.workers), chunk_episodes=int(cfg.chunk_episodes),
                                        seed=int(cfg.seed), overwrite=bool(cfg.overwrite))
    print("done:", summary)
    return summary


def teacher_options(cfg: DictConfig) -> dict:
    """Every option of the teacher the demonstrations are collected with: the system ``teacher``'s, each overridden
    by a non-null ``oracle.<option>``."""
    spec = system_spec(cfg.systems, cfg.teacher, kinds=("privileged",))
    return privileged_options({**spec, **{k: v for k, v in OmegaConf.to_container(cfg.oracle).items() if v is not None}})


def demonstrations(cfg: DictConfig) -> dict:
    if (Path(cfg.out_dir) / "demos.json").exists():
        raise FileExistsError(f"{cfg.out_dir} already holds demonstrations: choose another out_dir or delete it")
    need_dataset(cfg)
    oracle = teacher_options(cfg)                     # a bad teacher refused before the simulator starts
    torch.manual_seed(cfg.seed)
    env = SapienBinEnv(cfg.dataset, seed=cfg.seed, **OmegaConf.to_container(cfg.env))
    settings = {k: v for k, v in OmegaConf.to_container(cfg, resolve=True).items() if k not in ("systems", "what")}
    return write_demonstration_set(cfg.out_dir, env, int(cfg.states), oracle, settings, progress=cfg.progress)


def episodes(cfg: DictConfig) -> str:
    need_dataset(cfg)
    text = random_episodes(cfg.out_dir, cfg.dataset, OmegaConf.to_container(cfg.reward), OmegaConf.to_container(cfg.env),
                           episodes=int(cfg.episodes), seed=int(cfg.seed), video_format=cfg.video_format)
    print(text)
    return text


KINDS = {"rollouts": rollouts, "frames": frames, "demonstrations": demonstrations, "episodes": episodes}


def collect(cfg: DictConfig):
    """What ``cfg.what`` names, collected as its config says."""
    return KINDS[cfg.what](cfg)


@hydra.main(config_path="conf", config_name="collect", version_base="1.3")
def main(cfg: DictConfig) -> None:
    exit_on_sigterm()
    collect(cfg)


if __name__ == "__main__":
    main()

"""Roll out one MQA system's frozen manipulation policy over the questions and store the episodes.

    python recipes/collect_rollouts.py system=random                 # train (3 rollouts per question) + test
    python recipes/collect_rollouts.py system=dqn_local              # greedy DQN(R_l) from runs/local
    python recipes/collect_rollouts.py system=privileged splits=[test]
    python recipes/collect_rollouts.py system=random questions=all_types    # all four question types
    python recipes/collect_rollouts.py system=privileged collection.env.answer_size=448   # + I_start / I_stop at 448 px
    python recipes/collect_rollouts.py system=random collection.backend=ray collection.workers=8 ray.address=auto

Writes ``${root}/rollouts/<questions>/<system>/<split>`` (an ``EpisodeStore``: memmap chunks written
atomically). Interrupted? Run the same command again: it collects only what is missing. Systems are
defined in recipes/conf/systems.yaml; ``mqa_rl.collectors.rollouts`` says what is stored. The answer camera
follows the VQA the rollouts are for (``vqa=counting``, the default: 448 px; ``vqa=eqa``: none).
"""

from __future__ import annotations

import mqa_rl  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch loads)

from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from mqa_rl.collectors.rollouts import collect_split
from mqa_rl.modules.systems import system_spec
from mqa_rl.training.signals import exit_on_sigterm


def collect(cfg: DictConfig) -> list[dict]:
    spec = system_spec(cfg.systems, cfg.system)
    if not Path(cfg.dataset).exists():
        raise FileNotFoundError(f"dataset {cfg.dataset} does not exist: make it with recipes/make_dataset.py")
    summaries = []
    for split in cfg.splits:
        summary = collect_split(Path(cfg.out_dir) / split, split, dataset=cfg.dataset, policy=spec,
                                questions=OmegaConf.to_container(cfg.questions),
                                collection=OmegaConf.to_container(cfg.collection, resolve=True), overwrite=cfg.overwrite,
                                progress=cfg.progress, ray_address=cfg.ray.address)
        print(f"{cfg.system} {split}: {summary}", flush=True)
        summaries.append(summary)
    return summaries


@hydra.main(config_path="conf", config_name="collect_rollouts", version_base="1.3")
def main(cfg: DictConfig) -> None:
    exit_on_sigterm()
    collect(cfg)


if __name__ == "__main__":
    main()

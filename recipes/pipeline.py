"""Run a multi-step pipeline: recipes one after another, as recipes/conf/pipeline/<name>.yaml lists them, each step
skipped when its output is there (or resumed by its recipe), one line per step with the time since the start.

    python recipes/pipeline.py pipeline=student                          # the learned push policy, ~15 min on 2 cores
    python recipes/pipeline.py pipeline=student teacher=countable own_stop=false root=runs/countable
    python recipes/pipeline.py pipeline=reward_variants student=runs/student 'variants=[global,local]'
    python recipes/pipeline.py pipeline=answering                        # the answering pipeline at a quick CPU scale
    python recipes/pipeline.py pipeline=table3 vqa_model=classes         # Table III at full scale, ~3 h
    python recipes/pipeline.py pipeline=encoder_scenes                   # the VQA encoder on 1,000 more scenes
    python recipes/pipeline.py pipeline=main                             # the main job's steps (tools/main.sh)
    python recipes/pipeline.py pipeline=student --cfg job                # its options and steps, resolved by Hydra

A pipeline's options are its config's top-level keys (the file says what each does). A wrong option or value, or a
missing input, is refused before any step runs (exit code 2); a failing step stops the pipeline with its command
(exit code 1): run the same command again once it is fixed, and the pipeline continues where it stopped. Paths are
relative to the repository root, as every recipe's defaults are. The step runner is ``mqa_rl.pipelines``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

from mqa_rl.pipelines import PipelineRefused, StepFailed, check_command_line, run_pipeline

RECIPES = Path(__file__).resolve().parent


@hydra.main(config_path="conf", config_name="pipeline", version_base="1.3")
def main(cfg: DictConfig) -> None:
    os.chdir(RECIPES.parent)                 # the steps' paths are the repository's, as the recipes' defaults are
    try:
        run_pipeline(cfg, RECIPES)
    except PipelineRefused as error:
        print(f"refused: {error}", file=sys.stderr)
        raise SystemExit(2) from None
    except StepFailed as error:
        print(str(error), file=sys.stderr)
        raise SystemExit(1) from None


if __name__ == "__main__":
    try:
        check_command_line(RECIPES / "conf", sys.argv[1:])
    except PipelineRefused as error:
        print(f"refused: {error}", file=sys.stderr)
        raise SystemExit(2) from None
    main()

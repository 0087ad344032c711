#!/usr/bin/env bash
# The main job: set up the machine if needed, then show the MQA system working from the shipped checkpoints
# (checkpoints/README.md), ~9 min on 2 CPU cores after set-up, dataset included: its steps are the pipeline
# recipes/conf/pipeline/main.yaml (the dataset; the shipped systems answering 40 test COUNTING questions per level,
# Table III beside the paper's -> runs/main/report/report.md; videos of the best system -> runs/main/videos).
# Every step resumes or skips what is done. Options of that pipeline pass through, e.g. questions_per_level=20.
# The full-scale pipelines are in the README's reproduce table.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
. tools/bootstrap.sh
python recipes/pipeline.py pipeline=main "$@"

#!/usr/bin/env bash
# The main job: set up the machine if needed, then show the MQA system working from the shipped checkpoints
# (checkpoints/README.md), ~6 min on 2 CPU cores after set-up, dataset included:
#   1. make the default dataset unless a valid one is there, and print its summary;
#   2. Table III in small: the systems whose policy and counting VQA ship (no manipulation, random, the learned
#      student with its learned stop, the privileged oracle) answer 30 test COUNTING questions per level each:
#      their test rollouts, the answers, accuracy per level beside the paper's, the answer prior and the perfect
#      counters                                                             -> runs/main/report (table3.md, ...)
#   3. videos of the learned student's episodes with its Q-map overlays    -> runs/main/videos
# Every step resumes or skips what is done. The full-scale pipelines (training, all 600 questions) are in the
# README's reproduce table; the quick training pipeline is `bash tools/answering_pipeline.sh`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
. tools/bootstrap.sh
. tools/steps.sh
SYSTEMS=no_manipulation,random,dqn_student,privileged

step "1/3 the dataset"
python recipes/make_dataset.py
step "2/3 the shipped systems answer 30 test COUNTING questions per level"
python recipes/evaluate.py answering=shipped vqa=counting vqa_dir=checkpoints/vqa_counting "report=[$SYSTEMS]" \
  fig7=false out_dir=runs/main/report
step "3/3 videos of the learned student with its stop"
python recipes/evaluate_policy.py run=checkpoints/dqn_geometric_student stop_critic=checkpoints/stop_geometric_student \
  episodes_per_level=1 'policies=[greedy]' video_episodes=1 out_dir=runs/main/videos
step "done: runs/main/report (table3.md, table3.png, per_type.md, policy.md, by_scene.md), runs/main/videos"

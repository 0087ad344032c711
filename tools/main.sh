#!/usr/bin/env bash
# The main job: set up the machine if needed, then run the pipeline:
#   1. make the default dataset unless a valid one is there, and print its summary;
#   2. run two random-policy episodes on it and write their videos next to a printed log;
#   3. the whole MQA pipeline at a quick CPU scale (tools/answering_pipeline.sh): DQN(R_l) briefly,
#      rollouts of four systems, VQA encoder pretraining, one VQA per system, Table III, videos;
#   4. the shipped learned policy (checkpoints/dqn_geometric_student with its learned stop, the one that beats
#      random at every level: docs/results.md "Where the policy stands"): greedy vs random on 5 test questions per
#      level, with a video per level and Q-map overlays (runs/main/shipped_student).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
. tools/bootstrap.sh
python recipes/make_dataset.py
python recipes/random_episodes.py
bash tools/answering_pipeline.sh
python recipes/evaluate_policy.py run=checkpoints/dqn_geometric_student stop_critic=checkpoints/stop_geometric_student \
  episodes_per_level=5 'policies=[greedy,random]' video_episodes=1 out_dir=runs/main/shipped_student

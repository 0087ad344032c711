#!/usr/bin/env bash
# The main job: set up the machine if needed, then show the MQA system working from the shipped checkpoints
# (checkpoints/README.md), ~9 min on 2 CPU cores after set-up, dataset included:
#   1. make the default dataset unless a valid one is there (2 processes), and print its summary;
#   2. Table III on a sample: no manipulation, random, our best learned system (the countable student pushing its
#      budget, answering from the frame its perception counts most in) and the privileged oracle answer
#      40 test COUNTING questions per level each with their shipped counting VQA: accuracy beside
#      the paper's, every system paired with no manipulation and random by question (95 % by scene), what the
#      sample can separate, the full test split's stored result beside      -> runs/main/report/report.md
#   3. videos of the best system's episodes with its Q-map overlays        -> runs/main/videos
# Every step resumes or skips what is done. The full-scale pipelines are in the README's reproduce table.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
. tools/bootstrap.sh
. tools/steps.sh
SYSTEMS=no_manipulation,random,dqn_countable_budget_kept,privileged     # ids of recipes/conf/systems.yaml
QUESTIONS=40

step "1/3 the dataset"
python recipes/make_dataset.py
step "2/3 the shipped systems answer $QUESTIONS test COUNTING questions per level"
python recipes/evaluate.py answering=shipped vqa=counting vqa_dir=checkpoints/vqa_counting "report=[$SYSTEMS]" \
  "questions.max_per_group.test=$QUESTIONS" stored_results=checkpoints/vqa_counting/test_split_results.json \
  videos_dir=runs/main/videos fig7=false out_dir=runs/main/report
step "3/3 videos of the best system's episodes"
python recipes/evaluate_policy.py system=dqn_countable_budget_kept episodes_per_level=1 'policies=[greedy]' \
  video_episodes=1 out_dir=runs/main/videos
step "done: open runs/main/report/report.md (Table III, paired differences, figure); videos in runs/main/videos"

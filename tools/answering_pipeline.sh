#!/usr/bin/env bash
# The whole MQA pipeline at a quick CPU scale (recipes' `answering=quick` profile) with the paper's VQA (vqa=eqa),
# after the dataset:
#   1. train DQN(R_l) briefly (480 frames)                           -> runs/quick/dqn_local
#   2. roll out random, no manipulation, DQN(R_l), privileged (40 train + 30 test COUNTING questions
#      per level; random twice per training question)               -> runs/quick/rollouts
#   3. pretrain the VQA encoder on the random rollouts' frames       -> runs/quick/encoder
#   4. train one VQA per system on its rollouts                       -> runs/quick/vqa
#   5. Table III as measured (+ per type, policies, Fig. 7)           -> runs/quick/report
#   6. videos of greedy DQN(R_l) episodes with Q-map overlays         -> runs/quick/videos
# Every step resumes or skips what is done, so an interrupted run continues where it stopped.
# Overrides for a smaller or relocated run: MQA_ROOT, MQA_EXTRA (all answering recipes),
# MQA_DQN (train_dqn.py), MQA_PRETRAIN, MQA_VQA (extra arguments of those recipes).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
ROOT=${MQA_ROOT:-runs/quick}
read -r -a EXTRA <<< "${MQA_EXTRA:-}"
read -r -a DQN <<< "${MQA_DQN:-collector.total_frames=480 collector.annealing_frames=320 collector.learning_starts=64 eval.interval_frames=480 eval.episodes=3 checkpoint.interval_frames=480 buffer.size=480}"
read -r -a PRETRAIN <<< "${MQA_PRETRAIN:-train.steps=100 train.batch_size=16 train.eval_interval=50 frames.max_frames=600}"
read -r -a VQA <<< "${MQA_VQA:-train.steps=600 train.eval_interval=100}"
A=(answering=quick "root=$ROOT" "systems.dqn_local.run=$ROOT/dqn_local" "${EXTRA[@]}")
SYSTEMS=random,no_manipulation,dqn_local,privileged     # ids of recipes/conf/systems.yaml
V=(vqa=eqa)                                             # the answering recipes' VQA (their default: counting)
. tools/steps.sh

step "1/6 DQN(R_l), briefly"
python recipes/train_dqn.py reward=local "out_dir=$ROOT/dqn_local" resume=true "${DQN[@]}"
step "2/6 rollouts of $SYSTEMS"
python recipes/collect.py what=rollouts -m "${A[@]}" "${V[@]}" "system=$SYSTEMS"
step "3/6 VQA encoder pretraining"
python recipes/pretrain.py part=vqa_encoder "${A[@]}" resume=true "${PRETRAIN[@]}"
step "4/6 a VQA per system"
python recipes/train_vqa.py -m "${A[@]}" "${V[@]}" "system=$SYSTEMS" resume=true "${VQA[@]}"
step "5/6 Table III"
python recipes/evaluate.py "${A[@]}" "${V[@]}" "report=[$SYSTEMS]"
step "6/6 videos of DQN(R_l)"
python recipes/evaluate_policy.py "run=$ROOT/dqn_local" "policies=[greedy]" episodes_per_level=1 video_episodes=1 \
  video_format=mp4 "out_dir=$ROOT/videos"
step "done: $ROOT/report (table3.md, table3.png, per_type.md, policy.md, fig7_rewards.png), $ROOT/videos"

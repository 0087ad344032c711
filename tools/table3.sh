#!/usr/bin/env bash
# The paper's Table III at full scale on the default dataset (answering=default: every COUNTING question,
# 3 random rollouts per training question), with the paper's VQA (vqa=eqa):
#   1. the three DQN variants at the default CPU config, unless runs/<variant> already holds a checkpoint
#   2. rollouts of random; the VQA encoder pretrained on their frames
#   3. per system (random, no manipulation, privileged, DQN(R_g), DQN(R_l), DQN(R_g+R_l)): rollouts, its VQA
#   4. Table III, per type, policies, Fig. 7                       -> runs/answering/report/counting-eqa
# Each system is complete before the next starts, and every step resumes or skips what is done, so an
# interrupted run continues where it stopped and evaluate.py reports the systems finished so far.
# MQA_EXTRA: overrides for every answering recipe (e.g. "root=runs/answering_b vqa=classes").
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
. tools/bootstrap.sh
read -r -a EXTRA <<< "${MQA_EXTRA:-}"
start=$SECONDS
step() { echo; echo "=== [$(( (SECONDS - start) / 60 )) min] $*"; }

for v in global local global_local; do
  if ! compgen -G "runs/$v/checkpoints/checkpoint-*" > /dev/null; then
    step "DQN($v), default CPU config"
    python recipes/train_dqn.py "reward=$v" "out_dir=runs/$v" resume=true
  fi
done
step "rollouts of random (the VQA encoder learns from their frames)"
python recipes/collect_rollouts.py "${EXTRA[@]}" system=random
step "VQA encoder pretraining"
python recipes/pretrain_vqa_encoder.py "${EXTRA[@]}" resume=true
for s in random no_manipulation privileged dqn_global dqn_local dqn_global_local; do
  step "rollouts of $s"
  python recipes/collect_rollouts.py "${EXTRA[@]}" "system=$s"     # random's: already complete, skipped
  step "VQA of $s"
  python recipes/train_vqa.py "${EXTRA[@]}" "system=$s" resume=true
done
step "Table III"
python recipes/evaluate.py "${EXTRA[@]}"
step "done"

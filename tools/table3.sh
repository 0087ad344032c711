#!/usr/bin/env bash
# The paper's Table III at full scale on the default dataset (answering=default: every COUNTING question,
# 3 random rollouts per training question), with the paper's VQA (vqa=eqa):
#   1. the three DQN variants at the default CPU config, unless runs/<variant> already holds a checkpoint
#   2. rollouts of no manipulation and random; the VQA encoder pretrained on random's frames
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
rollouts_and_vqa() {
  step "rollouts of $1"
  python recipes/collect_rollouts.py "${EXTRA[@]}" "system=$1"
  if [[ "${2:-}" == encoder ]]; then
    step "VQA encoder pretraining (random's frames)"
    python recipes/pretrain_vqa_encoder.py "${EXTRA[@]}" resume=true
  fi
  step "VQA of $1"
  python recipes/train_vqa.py "${EXTRA[@]}" "system=$1" resume=true
}
python recipes/collect_rollouts.py "${EXTRA[@]}" system=no_manipulation
rollouts_and_vqa random encoder
for s in no_manipulation privileged dqn_global dqn_local dqn_global_local; do
  rollouts_and_vqa "$s"
done
step "Table III"
python recipes/evaluate.py "${EXTRA[@]}"
step "done"

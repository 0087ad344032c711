#!/usr/bin/env bash
# The paper's Table III at full scale on the default dataset (answering=default: every COUNTING question,
# 3 random rollouts per training question), with the paper's VQA (vqa=eqa):
#   1. the three DQN variants: runs/<variant> if it holds a checkpoint, else the shipped policy
#      (checkpoints/dqn_<variant>, trained at the default CPU config), else trained here (~13 min each);
#      MQA_TRAIN=1 trains whatever runs/ lacks instead of using what ships
#   2. rollouts of random; the VQA encoder pretrained on their frames (~28 min), or the shipped one
#      (checkpoints/vqa_encoder, pretrained on the same frames) unless MQA_TRAIN=1
#   3. the rollouts of every system (random, no manipulation, privileged, DQN(R_g), DQN(R_l), DQN(R_g+R_l), our
#      student), then a VQA per system: one Hydra multirun each (-m system=...)
#   4. Table III, per type, policies, Fig. 7                       -> runs/answering/report/counting-eqa
# Every step resumes or skips what is done, so an interrupted run continues where it stopped, and evaluate.py
# reports the systems finished so far.
# MQA_VQA=classes: ours instead of EQA's head (the grounded class pool, docs/results.md "Which class is the question
#   about?") on the encoder pretrained on 1,000 more scenes (checkpoints/vqa_encoder_scenes; MQA_TRAIN=1 pretrains
#   one here on random's frames instead, tools/pretrain_encoder_scenes.sh remakes the shipped one);
#   the report goes to runs/answering/report/counting-classes.
# MQA_EXTRA: overrides for every answering recipe (e.g. "root=runs/answering_b").
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
. tools/bootstrap.sh
read -r -a EXTRA <<< "${MQA_EXTRA:-}"
. tools/steps.sh

for v in global local global_local; do
  if compgen -G "runs/$v/checkpoints/checkpoint-*" > /dev/null; then
    continue
  elif [ -z "${MQA_TRAIN:-}" ] && [ -f "checkpoints/dqn_$v/config.yaml" ]; then
    step "DQN($v): the shipped policy checkpoints/dqn_$v"
    EXTRA+=("systems.dqn_$v.run=checkpoints/dqn_$v")
  else
    step "DQN($v), default CPU config"
    python recipes/train_dqn.py "reward=$v" "out_dir=runs/$v" resume=true
  fi
done
VQA=("vqa=${MQA_VQA:-eqa}")
step "rollouts of random (the VQA encoder learns from their frames)"
python recipes/collect.py what=rollouts "${EXTRA[@]}" system=random "${VQA[@]}"
ENCODER=checkpoints/vqa_encoder
[ "${MQA_VQA:-eqa}" = classes ] && ENCODER=checkpoints/vqa_encoder_scenes
ROOT=runs/answering
for a in "${EXTRA[@]}"; do case $a in root=*) ROOT=${a#root=} ;; esac; done
if [ -z "${MQA_TRAIN:-}" ] && [ -f "$ENCODER/encoder.pt" ] && [ ! -d "$ROOT/encoder" ]; then
  step "VQA encoder: the shipped one, $ENCODER/encoder.pt"
  VQA+=("encoder.weights=$ENCODER/encoder.pt")
else
  step "VQA encoder pretraining"
  python recipes/pretrain.py part=vqa_encoder "${EXTRA[@]}" resume=true
fi
SYSTEMS=random,no_manipulation,dqn_global,dqn_local,dqn_global_local,privileged,dqn_student
step "rollouts of $SYSTEMS"
python recipes/collect.py what=rollouts -m "${EXTRA[@]}" "system=$SYSTEMS" "vqa=${MQA_VQA:-eqa}"   # random's: complete, skipped
step "a VQA per system"
python recipes/train_vqa.py -m "${EXTRA[@]}" "system=$SYSTEMS" resume=true "${VQA[@]}"
step "Table III"
# the seven systems made above (the config's dqfd_* come from tools/train_reward_variants.sh: MQA_EXTRA's report= wins)
python recipes/evaluate.py "report=[$SYSTEMS]" \
  "${EXTRA[@]}" "vqa=${MQA_VQA:-eqa}"

step "done"

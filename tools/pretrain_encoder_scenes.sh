#!/usr/bin/env bash
# The VQA encoder pretrained on more scenes than the dataset's 70 training ones (docs/results.md, "Which class is the
# question about?"): ~50 min on 2 CPU cores (measured: 22 + 5 + 29 min)
#   1. a pretraining-only dataset of the same 60 objects, another seed: 1,000 piled scenes (300 / 300 / 400)
#   2. random rollouts on it (COUNTING questions, 500 + 200 per level, one each): its frames and labels
#   3. EQA's CNN with context heads (encoder.head_width=64), 2,000 steps of 32 on those frames and the
#      main dataset's random training rollouts (which bash tools/table3.sh or collect.py what=rollouts system=random make)
# The test scenes of data/mqa are never seen. Running it again skips finished steps and resumes the pretraining.
#
#   bash tools/pretrain_encoder_scenes.sh [OUT]        # OUT defaults to runs/encoder_scenes
#   python recipes/train_vqa.py system=random vqa=classes encoder.weights=OUT/encoder.pt
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
. tools/bootstrap.sh
OUT=${1:-runs/encoder_scenes}
EXTRA=data/pretrain_s1
MAIN=runs/answering/rollouts/counting/random/train
. tools/steps.sh
[ -f "$MAIN/meta.json" ] || { echo "no random rollouts of the main dataset at $MAIN: run python recipes/collect.py what=rollouts system=random first" >&2; exit 1; }
if [ ! -f "$EXTRA/manifest.json" ]; then
  step "a pretraining-only dataset: 1,000 scenes, seed 1 -> $EXTRA"
  python recipes/make_dataset.py dataset.seed=1 "dataset.out_dir=$EXTRA" 'dataset.num_scenes={easy: 300, medium: 300, hard: 400}'
fi
step "random rollouts on it -> runs/pretrain_s1"
python recipes/collect.py what=rollouts root=runs/pretrain_s1 "dataset=$EXTRA" system=random vqa=eqa \
  'questions.max_per_group={train: 500, test: 200}' collection.repeats.train=1 progress=false   # the env's frames only
step "the encoder -> $OUT"
python recipes/pretrain.py part=vqa_encoder "out_dir=$OUT" encoder.head_width=64 frames.max_frames=7000 resume=true \
  "frames.stores=[$MAIN,runs/pretrain_s1/rollouts/counting/random/train,runs/pretrain_s1/rollouts/counting/random/test]"
step "done: $OUT/encoder.pt"

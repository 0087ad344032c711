#!/usr/bin/env bash
# The learned push policy end to end on 2 CPU cores (14-15 min measured four times; docs/notebook/policy_attempts.md:
# the whole student in under 30 minutes, no push twice, the image teacher's students):
#   1. the image teacher's demonstrations on the train split, two processes at once (2 x 600 states, ~1.5 min)
#      (MQA_TEACHER=refined: the refined teacher instead, its push the best of 9 simulated starts: 9-11.5 min,
#       the chain 22-24 min; its students beat random on hard in 3 runs of 5, the image teacher's in 4 of 4;
#       MQA_TEACHER=countable: the countable teacher: the refined oracle reading the full silhouettes,
#       serving the least visible target until the perfect counter's 20-px line, stopping when no simulated push
#       shows the targets better (~1 s per state); the student on R_c (reward=countable), its stop learnt on the
#       share of targets a counter misses, fit_stop.py value=uncountable)
#   2. the geometric student imitating them (profile=student: 2,500 updates, the shipped recognition)
#   3. its stop, learnt from its own never-stopping episodes on the train split (recipes/fit_stop.py)
#   4. with MQA_EVAL=<episodes per level>: greedy + learned stop vs random on the test split
#      (MQA_BASELINE=<an earlier evaluation's out_dir>: reuse its random episodes when they are the same questions)
#   Steps 3 and 4 run the policy with the profile's push memory (env.push_memory=1: no push twice in an episode).
#   MQA_OWN_STOP=0: no step 3 (a system that pushes its budget and answers from its kept frame needs no stop;
#   step 4 then measures that, docs/policy.md "The budget and the kept frame").
#
#   bash tools/train_student.sh [ROOT] [SEED] [train_dqn overrides ...]     # ROOT defaults to runs/student
#
# Running the same command again skips every finished step; an interrupted training or stop fit resumes
# (train_dqn.py resume=true, fit_stop.py's per-level cache), an interrupted demonstration set is collected
# again (it is written only when complete). Evaluate later with
#   python recipes/evaluate_policy.py run=ROOT/dqn stop_critic=ROOT/stop episodes_per_level=300
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
TEACHER=${MQA_TEACHER:-image}
REWARD=global
export MQA_STOP_VALUE=chi
case "$TEACHER" in         # the teacher is the system <TEACHER>_teacher of recipes/conf/systems.yaml
  image|refined) ;;        # the push the image and the segmentation say / the best of 9 simulated starts
  countable) REWARD=countable; MQA_STOP_VALUE=uncountable ;;
  *) echo "MQA_TEACHER must be 'image', 'refined' or 'countable', got '${TEACHER}'" >&2; exit 2 ;;
esac
. tools/bootstrap.sh
# the teacher's options a demonstration set of it records in demos.json (refine_radius, min_visible_fraction,
# require_gain, geometry, order), from the registry
WANT=$(python -c "
import sys; from omegaconf import OmegaConf
from mqa_rl.modules.frozen_policies import privileged_options
from mqa_rl.modules.systems import system_spec
o = privileged_options(system_spec(OmegaConf.load('recipes/conf/systems.yaml').systems, sys.argv[1]))
print(o['refine_radius'], float(o['min_visible_fraction']), str(o['require_gain']).lower(), o['geometry'], o['order'])" \
  "${TEACHER}_teacher")
ROOT=${1:-runs/student}
SEED=${2:-0}
shift $(( $# < 2 ? $# : 2 ))
. tools/steps.sh
# a ROOT may already hold demonstrations: only of the teacher asked for (reused), never silently of the other
for k in 0 1; do
  demos="$ROOT/demos_$k/demos.json"
  if [ -f "$demos" ]; then
    have=$(python -c "
import json, sys; o = json.load(open(sys.argv[1]))['oracle']
print(o.get('refine_radius', 0), float(o.get('min_visible_fraction', 0.3)), str(o.get('require_gain', False)).lower(),
      o.get('geometry', 'visible'), o.get('order', 'visible_first'))" "$demos")
    if [ "$have" != "$WANT" ]; then
      echo "$ROOT/demos_$k holds demonstrations of another teacher (oracle refine_radius, min_visible_fraction," \
           "require_gain, geometry, order = $have), not the $TEACHER teacher's ($WANT):" \
           "choose another ROOT, set MQA_TEACHER to match, or remove $ROOT/demos_$k" >&2
      exit 2
    fi
  fi
done

[ -d data/mqa ] || { step "the dataset (python recipes/make_dataset.py)"; python recipes/make_dataset.py; }

step "demonstrations of the $TEACHER teacher: 2 x ${MQA_DEMO_STATES:-600} states, two processes -> $ROOT/demos_{0,1}"
pids=()
for k in 0 1; do
  if [ ! -f "$ROOT/demos_$k/demos.json" ]; then
    python recipes/collect.py what=demonstrations "states=${MQA_DEMO_STATES:-600}" "seed=$(( 2 * SEED + k + 100 ))" \
      "teacher=${TEACHER}_teacher" progress=false \
      "out_dir=$ROOT/demos_$k" &
    pids+=($!)
  fi
done
for p in "${pids[@]}"; do wait "$p"; done

step "the geometric student: imitation updates -> $ROOT/dqn"
python recipes/train_dqn.py dataset=data/mqa "reward=$REWARD" profile=student \
  "demos.path=[$ROOT/demos_0,$ROOT/demos_1]" "seed=$SEED" "out_dir=$ROOT/dqn" resume=true "$@"

fit_own_stop "$ROOT"
step "trained: $ROOT/dqn with $ROOT/stop"
evaluate_on_test "$ROOT"
step "done"

# Helpers of the multi-step scripts in tools/; sourced, not run.
#   step MESSAGE        prints MESSAGE with the time since the sourcing script started
#   fit_own_stop ROOT   the stop learnt from ROOT/dqn's own pushes on the train split -> ROOT/stop (skipped when done);
#                       MQA_STOP_VALUE=uncountable: it minimises the share of targets a counter misses, not χ
#   evaluate_on_test ROOT   with MQA_EVAL=<episodes per level>: greedy + learned stop vs random on the test split
#                       -> ROOT/eval (MQA_BASELINE=<an earlier evaluation's out_dir>: reuse its random episodes)
# Both run the policy with its run's push memory (fit_stop.py and evaluate_policy.py read it from ROOT/dqn).
start=$SECONDS
step() { echo "=== [$(( (SECONDS - start) / 60 )) min $(( (SECONDS - start) % 60 )) s] $*"; }
fit_own_stop() {
  if [ ! -f "$1/stop/stop_critic.pt" ]; then
    step "its stop, from its own pushes on the train split -> $1/stop"
    python recipes/fit_stop.py "run=$1/dqn" episodes_per_level=100 "value=${MQA_STOP_VALUE:-chi}" "out_dir=$1/stop"
  fi
}
evaluate_on_test() {
  if [ -n "${MQA_EVAL:-}" ]; then
    step "test split: greedy + learned stop vs random, $MQA_EVAL episodes per level -> $1/eval"
    python recipes/evaluate_policy.py "run=$1/dqn" "stop_critic=$1/stop" "episodes_per_level=$MQA_EVAL" \
      'policies=[greedy,random]' video_episodes=0 "out_dir=$1/eval" ${MQA_BASELINE:+"baseline_from=$MQA_BASELINE"}
  fi
}

# Helpers of the multi-step scripts in tools/; sourced, not run.
#   step MESSAGE        prints MESSAGE with the time since the sourcing script started
#   fit_own_stop ROOT   the stop learnt from ROOT/dqn's own pushes on the train split -> ROOT/stop (skipped when done);
#                       MQA_STOP_VALUE=uncountable: it minimises the share of targets a counter misses, not χ;
#                       MQA_OWN_STOP=0: no stop fitted (a system that pushes its budget and answers from its kept
#                       frame needs none; docs/policy.md)
#   evaluate_on_test ROOT   with MQA_EVAL=<episodes per level>: greedy + learned stop vs random on the test split
#                       (MQA_OWN_STOP=0: greedy pushing its budget, measured on the frame the shipped perception keeps)
#                       -> ROOT/eval (MQA_BASELINE=<an earlier evaluation's out_dir>: reuse its random episodes)
# Both run the policy with its run's push memory (fit_stop.py and evaluate_policy.py read it from ROOT/dqn).
MQA_OWN_STOP="${MQA_OWN_STOP:-1}"
case "$MQA_OWN_STOP" in    # refused before any step writes
  0|1) ;;
  *) echo "MQA_OWN_STOP must be 1 (fit the policy's own stop, the default) or 0 (none), got '$MQA_OWN_STOP'" >&2; exit 2 ;;
esac
start=$SECONDS
step() { echo "=== [$(( (SECONDS - start) / 60 )) min $(( (SECONDS - start) % 60 )) s] $*"; }
fit_own_stop() {
  if [ "$MQA_OWN_STOP" = 0 ]; then step "no stop fitted (MQA_OWN_STOP=0)"; return 0; fi
  if [ ! -f "$1/stop/stop_critic.pt" ]; then
    step "its stop, from its own pushes on the train split -> $1/stop"
    python recipes/fit_stop.py "run=$1/dqn" episodes_per_level=100 "value=${MQA_STOP_VALUE:-chi}" "out_dir=$1/stop"
  fi
}
evaluate_on_test() {
  if [ -n "${MQA_EVAL:-}" ]; then
    if [ "$MQA_OWN_STOP" = 0 ]; then    # its budget of pushes, measured on the frame the perception counts most in
      how=(stop_margin=inf kept_frame=checkpoints/vqa_counting/perception.pt); what="its budget, kept frame"
    else
      how=("stop_critic=$1/stop"); what="learned stop"
    fi
    step "test split: greedy ($what) vs random, $MQA_EVAL episodes per level -> $1/eval"
    python recipes/evaluate_policy.py "run=$1/dqn" "${how[@]}" "episodes_per_level=$MQA_EVAL" \
      'policies=[greedy,random]' video_episodes=0 "out_dir=$1/eval" ${MQA_BASELINE:+"baseline_from=$MQA_BASELINE"}
  fi
}

#!/usr/bin/env bash
# The test suite: set up the machine if needed (packages, Vulkan, Debian's headless Chromium), then run
# pytest over a lane. Tests are organised by layer: tests/unit (no simulator), tests/integration (real
# SAPIEN scenes, in-process recipes), tests/e2e (recipes and scripts launched as a user launches them,
# the browser); tests marked `slow` (full dataset, physics stress, kill-and-resume) run only in their lane.
#   bash tools/test.sh          every test, layer by layer (what CI runs)
#   bash tools/test.sh fast     unit + integration, not slow (the lane to run while working: <= 8 min)
#   bash tools/test.sh e2e      tests/e2e, not slow
#   bash tools/test.sh slow     the slow tests of every layer
#   bash tools/test.sh ray      tests/ray: the Ray backends on a real two-node cluster on this machine's loopback
#                               (ray start --head + a second ray start, one CPU each, stopped at the end)
# Extra arguments go to pytest, e.g. `bash tools/test.sh fast tests/integration/test_env.py -x`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
lane=all
case "${1:-}" in
    all|fast|e2e|slow|ray) lane=$1; shift ;;
    --all) shift ;;                       # the old spelling of `all`
esac
. tools/bootstrap.sh
case $lane in
    fast) args=(-m "not slow" tests/unit tests/integration) ;;
    e2e)  bash tools/browser.sh; args=(-m "not slow" tests/e2e) ;;
    slow) args=(-m slow tests) ;;
    ray)  args=(-m "not slow" tests/ray) ;;
    all)  bash tools/browser.sh; args=(tests/unit tests/integration tests/e2e tests/ray) ;;
esac
# paths given after the lane replace the lane's folders (the marker stays)
for a in "$@"; do
    case $a in tests/*) args=("${args[@]:0:2}"); [ "$lane" = all ] && args=(); break ;; esac
done
python -m pytest "${args[@]}" -q -p no:cacheprovider --timeout=1200 --durations=15 "$@"

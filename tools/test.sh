#!/usr/bin/env bash
# The test suite: set up the machine if needed (packages, Vulkan, Debian's headless Chromium), then
# run pytest. The fast lane skips tests marked slow; `tools/test.sh --all` runs everything. Extra
# arguments go to pytest.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
. tools/bootstrap.sh
bash tools/browser.sh          # headless Chromium for the demo's browser test: installed, never skipped
marker=(-m "not slow")
if [ "${1:-}" = "--all" ]; then marker=(); shift; fi
python -m pytest "${marker[@]}" -q -p no:cacheprovider --timeout=900 "$@"

#!/usr/bin/env bash
# The main job: set up the machine if needed, then run the pipeline (for now: make the default
# dataset unless it is there, and print its summary). Extra arguments go to the dataset recipe.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
. tools/bootstrap.sh
python recipes/make_dataset.py "$@"

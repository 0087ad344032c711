#!/usr/bin/env bash
# Set up everything mqa_rl needs on a bare Debian 12 machine, idempotently:
#   1. a virtualenv (.venv) with the pinned Python packages (requirements.lock), extras included
#      (the 'arm' extra's mani_skill without its dependencies: only its robot asset files are used),
#   2. a Vulkan device SAPIEN can render with: when none is usable, Mesa >= 24.3 lavapipe
#      from bookworm-backports (Debian 12's own Mesa 22 is too old; see docs/platform.md).
# A second run only checks: the venv carries a stamp of the lock file it was built from.
# Source it (`. tools/bootstrap.sh`) to get the venv activated in the calling shell.
# Set-up knobs, from the environment (the only MQA_* variables: what the recipes do is Hydra's config):
#   MQA_VENV=<dir>        where the virtualenv goes (default: .venv of this checkout; one venv may serve two checkouts)
#   MQA_MIN_FREE_GB=<n>   the free disk, in GB, asked for before installing the packages (default 9)
#   PYTHON=<python3.11>   the interpreter that makes the virtualenv (default python3)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${MQA_VENV:-$ROOT/.venv}"
PY="${PYTHON:-python3}"
LOCK="$ROOT/requirements.lock"
log() { printf '[bootstrap] %s\n' "$*" >&2; }

# --- 1. virtualenv + packages ------------------------------------------------------------
stamp="$VENV/.mqa-lock-stamp"
# the files' contents, not their paths: a venv shared by two checkouts (MQA_VENV) is not rebuilt, nor its
# editable install moved from one checkout to the other under running jobs (PYTHONPATH below picks the code)
want="$(cat "$LOCK" "$ROOT/pyproject.toml" | sha256sum | cut -d' ' -f1)"
if [ ! -x "$VENV/bin/python" ]; then
    log "creating virtualenv $VENV"
    "$PY" -m venv "$VENV"
fi
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    # The pinned stack takes ~7 GB once installed (torch with its CUDA wheels, sapien, ...): check
    # first, so that a full disk is named as such instead of surfacing as a pip OSError mid-install.
    need_gb="${MQA_MIN_FREE_GB:-9}"
    free_gb=$(( $(df -Pk "$VENV" | awk 'NR==2 {print $4}') / 1048576 ))
    if [ "$free_gb" -lt "$need_gb" ]; then
        log "ERROR: only ${free_gb} GB free on the disk of $VENV; installing the packages needs about ${need_gb} GB."
        log "Free some space (or point MQA_VENV at a larger disk) and run this script again."
        exit 1
    fi
    log "installing pinned packages (first run: several GB, a few minutes; log: $VENV/pip-install.log)"
    # Lines of the lock marked "# no-deps" are installed without their dependencies: of mani_skill
    # (the arm's robot assets, the 'arm' extra) only the asset files are used, not its heavy stack.
    { grep -v -- '# no-deps' "$LOCK" || true; } > "$VENV/requirements.core.txt"
    { grep -- '# no-deps' "$LOCK" || true; } | sed 's/#.*//' > "$VENV/requirements.no-deps.txt"
    if ! { "$VENV/bin/python" -m pip install --upgrade pip \
           && "$VENV/bin/python" -m pip install -r "$VENV/requirements.core.txt" \
           && { [ ! -s "$VENV/requirements.no-deps.txt" ] || "$VENV/bin/python" -m pip install --no-deps -r "$VENV/requirements.no-deps.txt"; } \
           && "$VENV/bin/python" -m pip install --no-deps -e "$ROOT"; } > "$VENV/pip-install.log" 2>&1; then
        tail -n 30 "$VENV/pip-install.log" >&2
        log "ERROR: package installation failed (full log: $VENV/pip-install.log)"
        if grep -q 'No space left on device' "$VENV/pip-install.log"; then
            log "The disk filled up during the install: free some space and run this script again."
        fi
        exit 1
    fi
    echo "$want" > "$stamp"
else
    log "virtualenv up to date"
fi

# --- 2. a Vulkan device for SAPIEN ---------------------------------------------------------
vulkan_ok() { "$VENV/bin/python" -c "import sapien; sapien.render.RenderSystem()" >/dev/null 2>&1; }
if vulkan_ok; then
    log "Vulkan rendering device found"
else
    if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then
        log "ERROR: SAPIEN found no Vulkan device. Install Mesa >= 24.3 (mesa-vulkan-drivers) or a GPU driver, as root."
        exit 1
    fi
    . /etc/os-release
    log "no usable Vulkan device: installing Mesa lavapipe from ${VERSION_CODENAME}-backports"
    if [ "${VERSION_CODENAME:-}" = bookworm ]; then
        # backports from the Debian mirror this machine already uses (never a fixed host)
        . "$ROOT/tools/debian_mirror.sh"
        if ! uri=$(debian_main_uri); then
            log "ERROR: no Debian 'bookworm ... main' entry found in /etc/apt/sources.list or /etc/apt/sources.list.d/."
            log "Add your mirror's line to /etc/apt/sources.list, e.g.:  deb <your Debian mirror URI> bookworm main"
            log "then run this script again."
            exit 1
        fi
        log "bookworm-backports from $uri"
        echo "deb $uri bookworm-backports main" > /etc/apt/sources.list.d/mqa-backports.list
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq -t bookworm-backports mesa-vulkan-drivers libvulkan1 >/dev/null
    else
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mesa-vulkan-drivers libvulkan1 >/dev/null
    fi
    if ! vulkan_ok; then
        log "ERROR: still no Vulkan device after installing Mesa; run: $VENV/bin/python -c 'import sapien; sapien.render.RenderSystem()'"
        exit 1
    fi
    log "Vulkan (lavapipe) ready"
fi
export PATH="$VENV/bin:$PATH"
export PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}"      # this checkout's mqa_rl, whichever the venv's editable install names
export VIRTUAL_ENV="$VENV"

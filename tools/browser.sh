#!/usr/bin/env bash
# Debian's headless Chromium and its driver (chromium, chromium-driver), for the web demo's end-to-end
# test (tests/e2e/test_demo_browser.py), installed with apt-get when missing; no browser build is
# downloaded at run time (selenium is pointed at /usr/bin/chromium and /usr/bin/chromedriver).
set -euo pipefail
log() { printf '[browser] %s\n' "$*" >&2; }
if command -v chromium >/dev/null && command -v chromedriver >/dev/null; then
    log "headless Chromium found: $(chromium --version 2>/dev/null | head -n 1)"
    exit 0
fi
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then
    log "ERROR: the demo's browser test needs Debian's chromium and chromium-driver; as root run:"
    log "  apt-get update && apt-get install -y chromium chromium-driver"
    exit 1
fi
log "installing chromium and chromium-driver (apt)"
apt-get update -qq
DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null
if ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then
    log "ERROR: chromium or chromedriver still missing after apt-get install"
    exit 1
fi
log "headless Chromium ready: $(chromium --version 2>/dev/null | head -n 1)"

#!/usr/bin/env bash
# The dashboard in a real browser: builds (or reuses) the debug binary, starts
# `aortagen serve` on a free port with a temporary database and a copy of models/, drives
# the page with playwright-core in the system's headless Chromium (installed with apt when
# missing; never a downloaded browser build), stops the server, and exits non-zero on any
# failed step or unexpected browser console error.
#
#   tests/browser/run.sh                       # screenshots are not kept
#   SCREENSHOT_DIR=docs/images tests/browser/run.sh   # refreshes the README's pictures
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/aortagen-target}"
chromium=/usr/bin/chromium

if [[ ! -x $chromium ]]; then
    echo "installing Debian's chromium"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
fi
if [[ ! -d tests/browser/node_modules/playwright-core ]]; then
    (cd tests/browser && npm ci --no-audit --no-fund --loglevel=error)
fi
# The viewer's distance map against brute force (node's own test runner, no packages).
node --test web/test/
cargo build --locked --quiet
binary="$CARGO_TARGET_DIR/debug/aortagen"

work=$(mktemp -d)
server_pid=""
cleanup() {
    if [[ -n $server_pid ]] && kill -0 "$server_pid" 2>/dev/null; then
        kill "$server_pid"
        wait "$server_pid" 2>/dev/null || true
    fi
    rm -rf "$work"
}
trap cleanup EXIT

cp -r models "$work/models"
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$binary" serve --bind "127.0.0.1:$port" --database "sqlite://$work/aortagen.db" \
    --models-dir "$work/models" --workers 1 >"$work/server.log" 2>&1 &
server_pid=$!
for _ in $(seq 1 100); do
    curl -sf "http://127.0.0.1:$port/readyz" >/dev/null && break
    kill -0 "$server_pid" 2>/dev/null || { cat "$work/server.log"; exit 1; }
    sleep 0.2
done
curl -sf "http://127.0.0.1:$port/readyz" >/dev/null || { echo "the service did not start"; cat "$work/server.log"; exit 1; }

mkdir -p "$work/profile"
case "${SCREENSHOT_DIR:-}" in
    "") shots="" ;;
    /*) shots=$SCREENSHOT_DIR ;;
    *) shots=$root/$SCREENSHOT_DIR ;;
esac
status=0
DASHBOARD_URL="http://127.0.0.1:$port" CHROMIUM="$chromium" USER_DATA_DIR="$work/profile" \
    SCREENSHOT_DIR="$shots" node tests/browser/dashboard.spec.js || status=$?
if [[ $status -ne 0 ]]; then
    echo "--- server log (last 40 lines)"
    tail -n 40 "$work/server.log"
fi
exit "$status"

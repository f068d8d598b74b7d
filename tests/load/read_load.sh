#!/usr/bin/env bash
# Read load on a busy service: a release `aortagen serve` (2 workers) on a temporary database
# with the bundled model; while a 20-shape cohort at 128³ keeps the workers busy, wrk runs
# 100 connections for 60 s on shape metadata and then on GLB downloads; then a burst of 1000
# cohort submissions must be answered 202 or 429 only, with every accepted cohort listed.
#
# Usage: tests/load/read_load.sh              (from the repository root)
# Env:   LOAD_SECONDS (default 60), LOAD_CONNECTIONS (default 100), LOAD_THREADS (wrk, default 2),
#        BURST (default 1000), LOAD_WORKERS (default 2), AORTAGEN_BIN (skip the build)
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/../.." && pwd)"
HERE="$ROOT/tests/load"
cd "$ROOT"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/aortagen-target}"
SECONDS_PER_RUN="${LOAD_SECONDS:-60}"
CONNECTIONS="${LOAD_CONNECTIONS:-100}"
WRK_THREADS="${LOAD_THREADS:-2}"
BURST="${BURST:-1000}"
WORKERS="${LOAD_WORKERS:-2}"

if ! command -v wrk >/dev/null; then
    apt-get install -y wrk >/dev/null 2>&1 || sudo apt-get install -y wrk
fi

if [ -n "${AORTAGEN_BIN:-}" ]; then
    BIN="$AORTAGEN_BIN" # an already built binary
else
    cargo build --release --locked --bin aortagen
    BIN="$CARGO_TARGET_DIR/release/aortagen"
fi

WORK="$(mktemp -d)"
PORT="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')"
BASE="http://127.0.0.1:$PORT"
mkdir -p "$WORK/models"
cp -r models/default "$WORK/models/default"

"$BIN" serve --bind "127.0.0.1:$PORT" --database "sqlite://$WORK/load.db" \
    --models-dir "$WORK/models" --workers "$WORKERS" >"$WORK/server.log" 2>&1 &
PID=$!
cleanup() {
    kill "$PID" 2>/dev/null || true
    wait "$PID" 2>/dev/null || true
    rm -rf "$WORK"
}
trap cleanup EXIT

alive() {
    if ! kill -0 "$PID" 2>/dev/null; then
        echo "FAIL: the server died" >&2
        tail -40 "$WORK/server.log" >&2
        exit 1
    fi
}
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }
post_cohort() {
    curl -fsS -X POST "$BASE/v1/cohorts" -H 'content-type: application/json' -d "$1" | json 'd["id"]'
}
rss() { awk '/VmHWM|VmRSS/ {printf "%s %.0f MiB  ", $1, $2/1024}' "/proc/$PID/status"; echo; }

for _ in $(seq 1 240); do
    if curl -fsS "$BASE/readyz" >/dev/null 2>&1; then break; fi
    alive
    sleep 0.5
done
curl -fsS "$BASE/readyz" >/dev/null

small=$(post_cohort '{"model_id":"default","count":2,"arity":2,"seed":1,"resolution":64}')
echo "small cohort $small queued; waiting for its first shape"
shape=""
for _ in $(seq 1 600); do
    shape=$(curl -fsS "$BASE/v1/cohorts/$small/shapes" | json 'd["items"][0]["id"] if d["items"] else ""')
    [ -n "$shape" ] && break
    alive
    sleep 1
done
[ -n "$shape" ] || { echo "FAIL: no shape after 600 s" >&2; exit 1; }
big=$(post_cohort '{"model_id":"default","count":20,"arity":3,"seed":2,"resolution":128}')
echo "shape $shape ready; big cohort $big queued (keeps the workers busy)"
sleep 2
curl -fsS "$BASE/v1/shapes/$shape/mesh" -o "$WORK/shape.glb"
echo "GLB size: $(stat -c %s "$WORK/shape.glb") bytes"

run_wrk() {
    local name=$1 path=$2
    echo "== $name: GET $path, $CONNECTIONS connections, $SECONDS_PER_RUN s"
    echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
    wrk -t "$WRK_THREADS" -c "$CONNECTIONS" -d "${SECONDS_PER_RUN}s" --timeout 10s \
        -s "$HERE/report.lua" "$BASE$path" | grep -E '^RESULT|Socket errors|Non-2xx'
    echo "load average after:  $(cut -d' ' -f1-3 /proc/loadavg)"
    echo "big cohort: $(curl -fsS "$BASE/v1/cohorts/$big" | json 'd["status"], d["progress"]')"
    echo "server memory: $(rss)"
    alive
}
run_wrk metadata "/v1/shapes/$shape"
run_wrk mesh "/v1/shapes/$shape/mesh"

echo "== burst: $BURST x POST /v1/cohorts"
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
python3 "$HERE/burst.py" 127.0.0.1 "$PORT" "$BURST" 50
alive
curl -fsS "$BASE/healthz" >/dev/null
echo "server memory: $(rss)"
echo "OK"

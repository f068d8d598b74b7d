#!/usr/bin/env bash
# Property-based API test: schemathesis generates requests from the served OpenAPI document
# (valid and invalid) against a release `aortagen serve` on a temporary database, and fails
# on any 5xx, undocumented status, wrong content type or body that breaks its schema.
#
# Usage: tests/schemathesis/run.sh            (from the repository root)
# Env:   ST_MAX_EXAMPLES (default 150 per operation and phase), ST_SEED (default 20261129),
#        ST_REPORT_DIR (JUnit reports; default target/schemathesis)
# One schemathesis worker: parallel workers hit a race in hypothesis's lambda-source cache.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/../.." && pwd)"
cd "$ROOT"
SCHEMATHESIS_VERSION=4.32.5
VENV="$HOME/.cache/aortagen-schemathesis"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/aortagen-target}"
MAX_EXAMPLES="${ST_MAX_EXAMPLES:-150}"
SEED="${ST_SEED:-20261129}"

if ! "$VENV/bin/st" --version 2>/dev/null | grep -q "$SCHEMATHESIS_VERSION"; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install --quiet --upgrade pip
    "$VENV/bin/pip" install --quiet "schemathesis==$SCHEMATHESIS_VERSION"
fi

cargo build --release --locked --bin aortagen
BIN="$CARGO_TARGET_DIR/release/aortagen"

WORK="$(mktemp -d)"
PORT="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')"
BASE="http://127.0.0.1:$PORT"
# A copy of the bundled model, so generated DELETE /v1/models requests never touch the tree.
mkdir -p "$WORK/models"
cp -r models/default "$WORK/models/default"

# One worker, a queue of 4 and a budget of 4 shapes at 32³ beside the first reconstruction
# of the bundled model's 16 training shapes: generated cohorts stay cheap.
"$BIN" serve --bind "127.0.0.1:$PORT" --database "sqlite://$WORK/st.db" \
    --models-dir "$WORK/models" --workers 1 --max-queue 4 \
    --max-cohort-voxels $(((4 + 16) * 32 * 32 * 32)) --max-count 4 \
    >"$WORK/server.log" 2>&1 &
PID=$!
cleanup() {
    kill "$PID" 2>/dev/null || true
    wait "$PID" 2>/dev/null || true
    rm -rf "$WORK"
}
trap cleanup EXIT

for _ in $(seq 1 120); do
    if curl -fsS "$BASE/readyz" >/dev/null 2>&1; then break; fi
    if ! kill -0 "$PID" 2>/dev/null; then cat "$WORK/server.log"; exit 1; fi
    sleep 0.5
done
curl -fsS "$BASE/readyz" >/dev/null

# A finished cohort, so the second pass reaches real shapes, jobs, metrics and reports.
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }
COHORT=$(curl -fsS -X POST "$BASE/v1/cohorts" -H 'content-type: application/json' \
    -d '{"model_id":"default","count":2,"arity":2,"seed":1,"resolution":32}' | json 'd["id"]')
for _ in $(seq 1 300); do
    state=$(curl -fsS "$BASE/v1/cohorts/$COHORT" | json 'd["status"]')
    metrics=$(curl -s -o /dev/null -w '%{http_code}' "$BASE/v1/cohorts/$COHORT/metrics")
    [ "$state" = succeeded ] && [ "$metrics" = 200 ] && break
    [ "$state" = failed ] && { echo "seed cohort failed" >&2; exit 1; }
    sleep 1
done
JOB=$(curl -fsS "$BASE/v1/cohorts/$COHORT" | json 'd["job_id"]')
SHAPE=$(curl -fsS "$BASE/v1/cohorts/$COHORT/shapes" | json 'd["items"][0]["id"]')
# A measurements-table reference and a finished validation of the cohort against it, so the
# validation operations are also reached with ids that exist.
printf 'patient_id;area_mm2;volume_mm3\np1;1000;2000\np2;1100;2100\np3;1200;2300\n' >"$WORK/ref.csv"
REFERENCE=$(curl -fsS -X POST "$BASE/v1/models/default/references" -F name=st \
    -F "table=@$WORK/ref.csv;filename=ref.csv" | json 'd["id"]')
VALIDATION=$(curl -fsS -X POST "$BASE/v1/cohorts/$COHORT/validations" \
    -H 'content-type: application/json' -d "{\"reference\":$REFERENCE}" | json 'd["id"]')
for _ in $(seq 1 120); do
    state=$(curl -fsS "$BASE/v1/validations/$VALIDATION" | json 'd["status"]')
    [ "$state" = succeeded ] && break
    [ "$state" = failed ] && { echo "seed validation failed" >&2; exit 1; }
    sleep 1
done
block() {
    printf '[[operations]]\ninclude-path-regex = "%s"\nparameters = { "path.id" = %s }\n\n' "$1" "$2"
}
{
    echo "# Second pass: path ids of existing resources; everything else is generated."
    block '^/v1/cohorts/[{]id[}]' "$COHORT"
    block '^/v1/jobs/[{]id[}]$' "$JOB"
    block '^/v1/shapes/[{]id[}]' "$SHAPE"
    block '^/v1/models/[{]id[}]' '"default"'
    block '^/v1/references/[{]id[}]' "$REFERENCE"
    block '^/v1/validations/[{]id[}]' "$VALIDATION"
} >"$WORK/known.toml"
CHECKS=not_a_server_error,response_schema_conformance,status_code_conformance,content_type_conformance
REPORT="${ST_REPORT_DIR:-$ROOT/target/schemathesis}"
mkdir -p "$REPORT"
STATUS=0
# run_pass NAME [schemathesis option…] [-- run option…]
# /v1/events is a stream that stays open for minutes: not a request/response to fuzz.
run_pass() {
    local name=$1
    shift
    local global=() extra=()
    while [ $# -gt 0 ] && [ "$1" != -- ]; do global+=("$1"); shift; done
    [ $# -gt 0 ] && shift
    extra=("$@")
    echo "== schemathesis pass: $name"
    "$VENV/bin/st" "${global[@]}" run "$BASE/openapi.json" \
        --checks "$CHECKS" --phases examples,coverage,fuzzing \
        --max-examples "$MAX_EXAMPLES" --seed "$SEED" --workers 1 \
        --request-timeout 60 --suppress-health-check all \
        --exclude-path /v1/events \
        --report junit --report-junit-path "$REPORT/$name.xml" --no-color "${extra[@]}" || STATUS=1
}
# Known ids first, without DELETE and cancel, which would remove what it reads; then
# every operation with generated ids.
run_pass known-ids --config-file "$WORK/known.toml" -- \
    --exclude-method DELETE --exclude-path-regex 'cancel$'
run_pass generated-ids
if ! kill -0 "$PID" 2>/dev/null; then
    echo "the server died during the run" >&2
    tail -50 "$WORK/server.log" >&2
    exit 1
fi
echo "cohort $COHORT, shape $SHAPE, job $JOB, reference $REFERENCE, validation $VALIDATION; reports in $REPORT"
exit "$STATUS"

#!/usr/bin/env bash
# Scale-out figures (tests/scale/run.py): builds the binary (the dev profile: dependencies at
# opt-level 3, this crate at 1, as the tests use it), starts PostgreSQL and an
# S3-compatible server, and generates one cohort with 1 then 2 worker processes.
#   SCALE_COUNT, SCALE_RESOLUTION override the cohort (40 shapes at 64³).
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/aortagen-target}"
# AORTAGEN_BINARY: an already built binary to run instead of building one.
binary="${AORTAGEN_BINARY:-$CARGO_TARGET_DIR/debug/aortagen}"
[[ -n "${AORTAGEN_BINARY:-}" ]] || cargo build --locked --quiet
work=$(mktemp -d /tmp/aortagen-scale.XXXXXX)
chmod 755 "$work" # the PostgreSQL server runs as another user under it
cleanup() {
    tests/support/postgres.sh stop "$work/pg"
    tests/support/s3-server.sh stop "$work/s3"
    rm -rf "$work"
}
trap cleanup EXIT
server=$(tests/support/postgres.sh start "$work/pg")
s3_env=$(tests/support/s3-server.sh start "$work/s3")
eval "$s3_env"
export AORTAGEN_BLOB_STORE="${AORTAGEN_BLOB_STORE:-s3://aortagen/scale}"
mkdir -p "$work/models"
cp -r "$root/models/default" "$work/models/default"
python3 tests/scale/run.py "$binary" "$work/models" "$server" "$work"

#!/usr/bin/env bash
# The multi-process fault test (tests/fault/run.py): builds the binary, starts a PostgreSQL
# server (tests/support/postgres.sh) and an S3-compatible one (tests/support/s3-server.sh;
# AORTAGEN_BLOB_STORE overrides the store), runs one API and four workers with faults
# injected, and compares the result with a single-process SQLite run.
#   FAULT_COUNT, FAULT_RESOLUTION, FAULT_MIN_FAULTS override the defaults (200, 32, 10).
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/aortagen-target}"
# AORTAGEN_BINARY: an already built binary to run instead of building one.
binary="${AORTAGEN_BINARY:-$CARGO_TARGET_DIR/debug/aortagen}"
[[ -n "${AORTAGEN_BINARY:-}" ]] || cargo build --locked --quiet
work=$(mktemp -d /tmp/aortagen-fault.XXXXXX)
chmod 755 "$work" # the PostgreSQL server runs as another user under it
pg_dir="$work/pg"
s3_dir="$work/s3"
cleanup() {
    tests/support/postgres.sh stop "$pg_dir"
    tests/support/s3-server.sh stop "$s3_dir"
    rm -rf "$work"
}
trap cleanup EXIT
server=$(tests/support/postgres.sh start "$pg_dir")
s3_env=$(tests/support/s3-server.sh start "$s3_dir")
eval "$s3_env"
export AORTAGEN_BLOB_STORE="${AORTAGEN_BLOB_STORE:-s3://aortagen/fault}"
psql "$server" -q -c "create database fault"
mkdir -p "$work/models"
cp -r "$root/models/default" "$work/models/default"
python3 tests/fault/run.py "$binary" "$work/models" "${server%/*}/fault" "$work"

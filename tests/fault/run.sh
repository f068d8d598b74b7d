#!/usr/bin/env bash
# The multi-process fault test (tests/fault/run.py): builds the binary, starts a PostgreSQL
# server (tests/support/postgres.sh), runs one API and four workers against it with faults
# injected, and compares the result with a single-process SQLite run.
#   FAULT_COUNT, FAULT_RESOLUTION, FAULT_MIN_FAULTS override the defaults (200, 32, 10).
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/aortagen-target}"
cargo build --locked --quiet
binary="$CARGO_TARGET_DIR/debug/aortagen"
work=$(mktemp -d /tmp/aortagen-fault.XXXXXX)
pg_dir="$work/pg"
cleanup() { tests/support/postgres.sh stop "$pg_dir"; rm -rf "$work"; }
trap cleanup EXIT
server=$(tests/support/postgres.sh start "$pg_dir")
psql "$server" -q -c "create database fault"
mkdir -p "$work/models"
cp -r "$root/models/default" "$work/models/default"
python3 tests/fault/run.py "$binary" "$work/models" "${server%/*}/fault" "$work"

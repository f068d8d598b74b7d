#!/usr/bin/env bash
# A throwaway S3-compatible server for the tests: s3s-fs from crates.io, installed once with
# cargo under $HOME/.cache/aortagen-tools (0.14.1: later releases need a newer Rust), serving
# a directory on a free local port with a fixed test key pair and one bucket, `aortagen`.
#
#   env=$(tests/support/s3-server.sh start DIR); eval "$env"
#       start it; the output exports AORTAGEN_TEST_S3_URL (s3://aortagen/tests) and the
#       AWS_* variables that reach it
#   tests/support/s3-server.sh stop DIR              stop it and remove DIR
set -euo pipefail

command=${1:?usage: s3-server.sh start|stop DIR}
dir=${2:?usage: s3-server.sh start|stop DIR}
tools="$HOME/.cache/aortagen-tools"
binary="$tools/bin/s3s-fs"

case "$command" in
start)
    if [[ ! -x "$binary" ]]; then
        echo "s3-server.sh: installing s3s-fs 0.14.1 from crates.io into $tools (once)" >&2
        cargo install --quiet --locked --root "$tools" s3s-fs --version 0.14.1 \
            --features binary >&2
    fi
    mkdir -p "$dir/data/aortagen"
    port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
    "$binary" --host 127.0.0.1 --port "$port" --access-key aortagen-test \
        --secret-key aortagen-test-secret "$dir/data" >"$dir/server.log" 2>&1 &
    echo $! >"$dir/pid"
    for _ in $(seq 100); do
        if (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null; then
            cat <<VARS
export AORTAGEN_TEST_S3_URL=s3://aortagen/tests
export AWS_ENDPOINT_URL=http://127.0.0.1:$port
export AWS_ACCESS_KEY_ID=aortagen-test
export AWS_SECRET_ACCESS_KEY=aortagen-test-secret
export AWS_REGION=us-east-1
export AWS_ALLOW_HTTP=true
VARS
            exit 0
        fi
        sleep 0.1
    done
    echo "s3-server.sh: s3s-fs did not start listening:" >&2
    cat "$dir/server.log" >&2
    exit 1
    ;;
stop)
    if [[ -f "$dir/pid" ]]; then
        kill "$(cat "$dir/pid")" 2>/dev/null || true
    fi
    rm -rf "$dir"
    ;;
*)
    echo "usage: s3-server.sh start|stop DIR" >&2
    exit 2
    ;;
esac

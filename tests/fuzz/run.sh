#!/usr/bin/env bash
# Runs every fuzz target for a fixed time (default 600 s each), one after the other, with the
# committed seeds as the starting corpus. Not part of CI. Needs a nightly toolchain and
# cargo-fuzz (`cargo install cargo-fuzz --locked`).
#   tests/fuzz/run.sh [SECONDS] [TARGET...]
set -euo pipefail
cd "$(dirname "$0")"
seconds="${1:-600}"
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(read_stl read_obj read_ply read_gltf cohort_request)
fi
# The crate forbids unsafe code, so the sanitizer adds little; without it the targets
# build faster and run several times more executions per second. Panics, aborts, timeouts
# and out-of-memory are still caught by libFuzzer.
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/aortagen-fuzz-target}"
for t in "${targets[@]}"; do
    corpus="corpus/$t"
    mkdir -p "$corpus"
    echo "== $t for ${seconds}s"
    cargo +nightly fuzz run --fuzz-dir . --sanitizer none "$t" "$corpus" "seeds/$t" -- \
        -max_total_time="$seconds" -rss_limit_mb=2048 -max_len=65536 -timeout=10 -print_final_stats=1
done

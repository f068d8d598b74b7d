#!/usr/bin/env bash
# Crash-safety run: SIGKILLs `aortagen serve` AORTAGEN_CRASH_ROUNDS times (default 20) at
# seeded random moments while cohorts and a training job run, then checks that every job
# finished exactly once. Set RELEASE=1 to build with the release profile.
set -euo pipefail
cd "$(dirname "$0")/../.."
export AORTAGEN_CRASH_ROUNDS="${AORTAGEN_CRASH_ROUNDS:-20}"
profile=()
if [[ "${RELEASE:-0}" == 1 ]]; then profile=(--release); fi
start=$(date +%s)
cargo test --locked "${profile[@]}" --test api crash_safety -- --nocapture
echo "crash safety: ${AORTAGEN_CRASH_ROUNDS} rounds passed in $(( $(date +%s) - start )) s (build included)"

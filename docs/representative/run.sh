#!/usr/bin/env bash
# The representativeness experiment of docs/representative/README.md: a SynthAorta model
# trained on 80 shapes with 20 held out, 100-shape cohorts of every sampler and setting,
# each validated against the held-out shapes and against the training shapes.
#   docs/representative/run.sh DATA_DIR [OUT_DIR]    (RESOLUTION=64 COUNT=100 SEED=2026 POINTS=2000;
#   AORTAGEN=path/to/binary to use a built binary instead of building one; EVALUATE=0 to skip
#   the held-out fitting of `aortagen evaluate`, which the validations do not need)
# Every step is skipped when its output exists, so an interrupted run continues.
set -euo pipefail
data="${1:?usage: run.sh DATA_DIR [OUT_DIR]}"
out="${2:-/tmp/aortagen-representative}"
resolution="${RESOLUTION:-64}"
seed="${SEED:-2026}"
points="${POINTS:-2000}"
source "$(dirname "$0")/../experiment.sh"
mkdir -p "$out"
model="$out/model-80"

if [ ! -f "$model/manifest.json" ] || ! grep -q '"complete": true' "$model/manifest.json"; then
    resume=()
    [ -f "$model/manifest.json" ] && resume=(--resume)
    timed train "$bin" train --data "$data" --out "$model" --preset cpu --seed "$seed" \
        --holdout 20 "${resume[@]}" > "$out/train.log" 2>&1
fi
if [ "${EVALUATE:-1}" != 0 ] && [ ! -f "$model/evaluation.json" ]; then
    timed evaluate "$bin" evaluate --model "$model" --resolution 128 \
        --json "$model/evaluation.json" > "$out/evaluate.log" 2>&1
fi

source docs/representative/common.sh
cohort() { # NAME GENERATE-FLAGS...
    local name="$1"
    shift
    generate_cohort "$out/cohorts/$name" "$model" "$seed" "$resolution" "$@"
}
mkdir -p "$out/cohorts"
cohort convex-a2 --arity 2
cohort convex-a4 --arity 4
cohort convex-a8 --arity 8
cohort convex-a4-noise1 --arity 4 --latent-noise 1
cohort pca --sampler pca-gaussian
cohort pca-t3 --sampler pca-gaussian --truncation 3
cohort pca-t2 --sampler pca-gaussian --truncation 2
cohort pca-t1.5 --sampler pca-gaussian --truncation 1.5
cohort pca-s1.1 --sampler pca-gaussian --sigma-scale 1.1
cohort pca-s1.2 --sampler pca-gaussian --sigma-scale 1.2
cohort gmm-k2 --sampler pca-mixture --components 2
cohort gmm-k4 --sampler pca-mixture --components 4
cohort gmm-bic --sampler pca-mixture --max-components 4

validate() { # NAME REFERENCE
    validate_cohort "$out/validation/$1-$2" "$out/cohorts/$1" "$model" "$2" "$points" "$seed"
}
mkdir -p "$out/validation"
cohorts=(convex-a2 convex-a4 convex-a8 convex-a4-noise1 pca pca-t3 pca-t2 pca-t1.5 pca-s1.1 pca-s1.2 gmm-k2 gmm-k4 gmm-bic)
for name in "${cohorts[@]}"; do validate "$name" heldout; done
for name in "${cohorts[@]}"; do validate "$name" training; done

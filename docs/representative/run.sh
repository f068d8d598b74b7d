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
count="${COUNT:-100}"
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

cohort() { # NAME GENERATE-FLAGS...
    local name="$1"
    shift
    if [ -f "$out/cohorts/$name/shape_$(printf %04d $((count - 1))).json" ]; then
        return
    fi
    echo "== $name: $*"
    timed "$name" "$bin" generate --model "$model" --count "$count" --seed "$seed" \
        --resolution "$resolution" --novelty-points 10000 --format ply \
        --out "$out/cohorts/$name" "$@" > "$out/cohorts/$name.log" 2>&1
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

# The goal figures as acceptance criteria, set before any validation runs.
criteria='{"nna_max": 0.55, "cov_at_least_baseline": true, "pairwise_median_tolerance": 0.15, "dcr_ratio_min": 1.0, "ks_p_min": 0.05}'
validate() { # NAME REFERENCE
    local name="$1" reference="$2"
    local report="$out/validation/$name-$reference"
    [ -f "$report.json" ] && return
    echo "== validate $name against $reference"
    timed "validate $name $reference" "$bin" validate --cohort "$out/cohorts/$name" \
        --reference "$reference" --model "$model" --criteria "$criteria" --points "$points" \
        --seed "$seed" --json "$report.json" --out "$report.html" > "$report.log" 2>&1
}
mkdir -p "$out/validation"
cohorts=(convex-a2 convex-a4 convex-a8 convex-a4-noise1 pca pca-t3 pca-t2 pca-t1.5 pca-s1.1 pca-s1.2 gmm-k2 gmm-k4 gmm-bic)
for name in "${cohorts[@]}"; do validate "$name" heldout; done
for name in "${cohorts[@]}"; do validate "$name" training; done

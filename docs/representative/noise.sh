#!/usr/bin/env bash
# How much of the shape-level verdict is noise (docs/representative/README.md, "How noisy
# are COV and DCR?"): on the model and cohorts run.sh leaves in OUT_DIR, at 10 000 points
# against the held-out shapes,
#   * cohorts of gmm-k2, pca and pca-s1.1 drawn again with cohort seeds 2027 and 2028;
#   * the model's reconstructions of its own 80 training shapes (64³ and 128³) as a cohort:
#     what a sampler that drew exactly the training latents would reach;
#   * gmm-k2 and pca-s1.1 meshed at 128³;
#   * pca-gaussian truncated at 1.5 / 2 with σ scaled to restore each mode's variance;
#   * gmm-k2, pca-s1.1 and the reconstructions validated with evaluation seeds 2027, 2028.
#   docs/representative/noise.sh OUT_DIR    (AORTAGEN=path/to/binary as in run.sh)
# Every step is skipped when its output exists. Summary: python3 docs/representative/table.py
# --noise OUT_DIR/noise
set -euo pipefail
out="${1:?usage: noise.sh OUT_DIR, the output directory of run.sh}"
source "$(dirname "$0")/../experiment.sh"
model="$out/model-80"
noise="$out/noise"
mkdir -p "$noise"
source docs/representative/common.sh

cohort() { # NAME SEED RESOLUTION GENERATE-FLAGS...
    local name="$1"
    shift
    generate_cohort "$noise/$name" "$model" "$@"
}
reconstructions() { # RESOLUTION: the training shapes meshed alone, as a cohort directory
    local resolution="$1" dir="$noise/reconstructions-$1"
    [ -d "$dir" ] && return
    echo "== reconstructions at ${resolution}³"
    timed "reconstructions $resolution" "$bin" evaluate --model "$model" \
        --resolution "$resolution" --points 10000 --heldout-iterations 0 \
        --worst "$noise/evaluate-$resolution" --worst-count 80 > "$noise/evaluate-$resolution.log" 2>&1
    mkdir -p "$dir.part"
    cp "$noise/evaluate-$resolution"/*_reconstruction.ply "$dir.part/"
    mv "$dir.part" "$dir"
}
validate() { # NAME COHORT-DIR EVALUATION-SEED
    validate_cohort "$noise/$1-v$3" "$2" "$model" heldout 10000 "$3"
}

for seed in 2027 2028; do
    cohort "gmm-k2-c$seed" "$seed" 64 --sampler pca-mixture --components 2
    cohort "pca-c$seed" "$seed" 64 --sampler pca-gaussian
    cohort "pca-s1.1-c$seed" "$seed" 64 --sampler pca-gaussian --sigma-scale 1.1
done
cohort gmm-k2-r128 2026 128 --sampler pca-mixture --components 2
cohort pca-s1.1-r128 2026 128 --sampler pca-gaussian --sigma-scale 1.1
cohort pca-t1.5-s1.346 2026 64 --sampler pca-gaussian --truncation 1.5 --sigma-scale 1.346
cohort pca-t2-s1.137 2026 64 --sampler pca-gaussian --truncation 2 --sigma-scale 1.137
reconstructions 64
reconstructions 128

for name in gmm-k2-c2027 gmm-k2-c2028 pca-c2027 pca-c2028 pca-s1.1-c2027 pca-s1.1-c2028 \
    gmm-k2-r128 pca-s1.1-r128 pca-t1.5-s1.346 pca-t2-s1.137; do
    validate "$name" "$noise/$name" 2026
done
for seed in 2026 2027 2028; do
    validate reconstructions-64 "$noise/reconstructions-64" "$seed"
done
validate reconstructions-128 "$noise/reconstructions-128" 2026
for seed in 2027 2028; do
    validate gmm-k2 "$out/cohorts/gmm-k2" "$seed"
    validate pca-s1.1 "$out/cohorts/pca-s1.1" "$seed"
done

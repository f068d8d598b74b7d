#!/usr/bin/env bash
# Two attempts at the gap to a new patient (docs/representative/README.md, "Shrinking the
# covariance, and a novelty floor"), on the model run.sh leaves in OUT_DIR, each over
# cohort seeds 2026–2028 and validated at 10 000 points against the held-out shapes
# (evaluation seed 2026), then against the training shapes; and the held-out shapes as the
# decoder renders them, for the DCR a perfect sampler would reach:
#   * pca-gaussian with the Ledoit–Wolf covariance, alone and with σ scaled back to the
#     population's pairwise spread;
#   * gmm-k2 with a novelty floor (`--min-novelty`, unit-ball Chamfer distance to the
#     nearest reconstructed training shape).
#   docs/representative/variants.sh OUT_DIR    (AORTAGEN=path/to/binary as in run.sh)
# Every step is skipped when its output exists. Summary: python3 docs/representative/table.py
# --variants OUT_DIR/variants
set -euo pipefail
out="${1:?usage: variants.sh OUT_DIR, the output directory of run.sh}"
source "$(dirname "$0")/../experiment.sh"
model="$out/model-80"
dir="$out/variants"
mkdir -p "$dir"
source docs/representative/common.sh

validate() { # REPORT-NAME COHORT-DIR REFERENCE POINTS: writes $dir/REPORT-NAME.{json,html,log}
    validate_cohort "$dir/$1" "$2" "$model" "$3" "$4" 2026
}

run() { # NAME SEED GENERATE-FLAGS...: cohort $dir/NAME-cSEED, report NAME-cSEED-v2026
    local name="$1-c$2" seed="$2"
    shift 2
    generate_cohort "$dir/$name" "$model" "$seed" 64 "$@"
    validate "$name-v2026" "$dir/$name" heldout 10000
}

gmm=(--sampler pca-mixture --components 2)
for seed in 2026 2027 2028; do
    run pca-lw "$seed" --sampler pca-gaussian --covariance ledoit-wolf
done
for seed in 2026 2027 2028; do
    run pca-lw-s1.09 "$seed" --sampler pca-gaussian --covariance ledoit-wolf --sigma-scale 1.09
done
for floor in ${FLOORS:-3.0e-4 3.3e-4}; do
    run "gmm-k2-n$floor" 2026 "${gmm[@]}" --min-novelty "$floor"
done
for seed in 2027 2028; do
    run "gmm-k2-n${SEED_FLOOR:-3.0e-4}" "$seed" "${gmm[@]}" --min-novelty "${SEED_FLOOR:-3.0e-4}"
done

# The same cohorts against the 80 training shapes at run.sh's 2 000 points, beside gmm-k2's
# (run.sh's validation/gmm-k2-training.json is cohort seed 2026).
for seed in 2026 2027 2028; do
    validate "pca-lw-s1.09-c$seed-training" "$dir/pca-lw-s1.09-c$seed" training 2000
done
for seed in 2027 2028; do
    validate "gmm-k2-c$seed-training" "$out/noise/gmm-k2-c$seed" training 2000
done

# The held-out shapes as the decoder renders them: each fitted with the network frozen
# (`aortagen fit`, on a copy of the model so the anchors stay out of it) and meshed at 64³
# as a cohort of one shape that is all anchor (weights 0 on a training shape, 1 on it). Validated against the held-out originals, their DCR ratio is what
# a sampler that drew exactly the new patients' latents would reach.
data="${DATA:-/work/shared/data/synthaorta/ref4}"
fits="$dir/model-80-heldout-fits"
rendered="$dir/heldout-reconstructions"
if [ ! -d "$rendered" ]; then
    mkdir -p "$fits" "$rendered.part"
    cp "$model"/manifest.json "$model"/weights.bpk "$model"/samples-*.bin "$fits/"
    names=$(python3 -c 'import json,sys; print(" ".join(s["name"] for s in json.load(open(sys.argv[1]))["data"]["holdout"]["shapes"]))' "$model/manifest.json")
    for name in $names; do
        if ! grep -q "\"$name\"" "$fits/anchors.json" 2>/dev/null; then
            timed "fit $name" "$bin" fit --model "$fits" --mesh "$data/$name.ply" --name "$name" \
                --resolution 64 --points 10000 > "$dir/fit-$name.log" 2>&1
        fi
        timed "mesh $name" "$bin" generate --model "$fits" --arity 2 --weights 0,1 --anchor "$name" \
            --count 1 --seed 1 --resolution 64 --novelty-points 10000 --format ply \
            --out "$dir/mesh-$name" > "$dir/mesh-$name.log" 2>&1
        cp "$dir/mesh-$name/shape_0000.ply" "$rendered.part/$name.ply"
    done
    mv "$rendered.part" "$rendered"
fi
validate heldout-reconstructions-v2026 "$rendered" heldout 10000

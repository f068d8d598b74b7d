#!/usr/bin/env bash
# Density samplers fitted to re-fitted latents (docs/representative/README.md, "Samplers fitted
# to re-fitted latents"), on the model run.sh leaves in OUT_DIR: every training shape is
# fitted once more with the network frozen, as a new patient is (`aortagen refit`, about
# 40 s per shape, resumable), then pca-gaussian (with the sample and with the Ledoit–Wolf
# covariance) and gmm-k2 are fitted to those latents (`--latents refitted`) over cohort
# seeds 2026–2028 and validated at 10 000 points against
# the held-out shapes (evaluation seed 2026), and seed 2026 against the training shapes.
#   docs/representative/refitted.sh OUT_DIR    (AORTAGEN=path/to/binary as in run.sh)
# Every step is skipped when its output exists. Summary: python3 docs/representative/table.py
# --variants OUT_DIR/refitted
set -euo pipefail
out="${1:?usage: refitted.sh OUT_DIR, the output directory of run.sh}"
source "$(dirname "$0")/../experiment.sh"
model="$out/model-80"
dir="$out/refitted"
data="${DATA:-/work/shared/data/synthaorta/ref4}"
mkdir -p "$dir"
source docs/representative/common.sh

# Resumes where an interrupted run stopped; prints the fits' median Chamfer distance and
# the spread of the re-fitted latents beside the training ones.
timed refit "$bin" refit --model "$model" --data "$data" > "$dir/refit.log" 2>&1
grep -E "Chamfer|latent distance" "$dir/refit.log"

validate() { # REPORT-NAME COHORT-DIR REFERENCE POINTS: writes $dir/REPORT-NAME.{json,html,log}
    validate_cohort "$dir/$1" "$2" "$model" "$3" "$4" 2026
}

run() { # NAME SEED GENERATE-FLAGS...: cohort $dir/NAME-cSEED, report NAME-cSEED-v2026
    local name="$1-c$2" seed="$2"
    shift 2
    generate_cohort "$dir/$name" "$model" "$seed" 64 "$@"
    validate "$name-v2026" "$dir/$name" heldout 10000
}

for seed in ${SEEDS:-2026 2027 2028}; do
    run gmm-k2-refitted "$seed" --sampler pca-mixture --components 2 --latents refitted
    run pca-refitted "$seed" --sampler pca-gaussian --latents refitted
done
# Ledoit–Wolf on the re-fitted latents: 80 latents in 68 dimensions leave the trailing
# modes of the sample covariance too narrow for the held-out latents.
for seed in ${SEEDS:-2026 2027 2028}; do
    run pca-lw-refitted "$seed" --sampler pca-gaussian --covariance ledoit-wolf --latents refitted
done
validate gmm-k2-refitted-c2026-training "$dir/gmm-k2-refitted-c2026" training 2000
validate pca-refitted-c2026-training "$dir/pca-refitted-c2026" training 2000

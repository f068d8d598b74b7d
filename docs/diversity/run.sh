#!/usr/bin/env bash
# The diversity experiment of docs/diversity/README.md: 100-shape cohorts of one model at
# arity 2, 4 and 8 and with each diversity control, compared side by side.
#   docs/diversity/run.sh MODEL_DIR [OUT_DIR]      (RESOLUTION=64 COUNT=100 SEED=2026;
#   AORTAGEN=path/to/binary to use a built binary instead of building one)
set -euo pipefail
model="${1:?usage: run.sh MODEL_DIR [OUT_DIR]}"
out="${2:-/tmp/aortagen-diversity}"
resolution="${RESOLUTION:-64}"
count="${COUNT:-100}"
seed="${SEED:-2026}"
source "$(dirname "$0")/../experiment.sh"
mkdir -p "$out"

cohort() { # NAME GENERATE-FLAGS...
    local name="$1"
    shift
    if [ -f "$out/$name/shape_$(printf %04d $((count - 1))).json" ]; then
        echo "== $name: already generated"
        return
    fi
    echo "== $name: $*"
    /usr/bin/time -f "$name: %e s, peak RSS %M KiB" \
        "$bin" generate --model "$model" --count "$count" --seed "$seed" \
        --resolution "$resolution" --units unit --format ply --out "$out/$name" "$@" \
        > "$out/$name.log"
}

cohort arity2 --arity 2
cohort arity4 --arity 4
cohort arity8 --arity 8
cohort arity4-noise1 --arity 4 --latent-noise 1
cohort arity4-spread --arity 4 --selection spread
cohort arity4-noise0.5 --arity 4 --latent-noise 0.5

"$bin" compare --training-model "$model" --resolution "$resolution" \
    --cohort "arity 2=$out/arity2" \
    --cohort "arity 4=$out/arity4" \
    --cohort "arity 8=$out/arity8" \
    --cohort "arity 4, noise 0.5σ=$out/arity4-noise0.5" \
    --cohort "arity 4, noise 1σ=$out/arity4-noise1" \
    --cohort "arity 4, spread=$out/arity4-spread" \
    --out "$out/diversity.html" --json "$out/diversity.json" --svg-dir "$out"

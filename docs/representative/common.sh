# Sourced by the scripts of docs/representative after ../experiment.sh (bash, run from the
# repository root): the goal as acceptance criteria, and the two steps every script repeats.
# Each step is skipped when its output exists, so an interrupted script continues.

# The goal figures of the experiment, set before any validation ran.
criteria='{"nna_max": 0.55, "cov_at_least_baseline": true, "pairwise_median_tolerance": 0.15, "dcr_ratio_min": 1.0, "ks_p_min": 0.05}'

generate_cohort() { # DIR MODEL SEED RESOLUTION GENERATE-FLAGS...: $COUNT (100) shapes in DIR, log DIR.log
    local dir="$1" model="$2" seed="$3" resolution="$4"
    shift 4
    local count="${COUNT:-100}" name
    name="$(basename "$dir")"
    [ -f "$dir/shape_$(printf %04d $((count - 1))).json" ] && return
    echo "== $name: seed $seed, ${resolution}³, $*"
    timed "$name" "$bin" generate --model "$model" --count "$count" --seed "$seed" \
        --resolution "$resolution" --novelty-points 10000 --format ply \
        --out "$dir" "$@" > "$dir.log" 2>&1
}

validate_cohort() { # REPORT COHORT-DIR MODEL REFERENCE POINTS EVALUATION-SEED: REPORT.{json,html,log}
    local report="$1" cohort="$2" model="$3" reference="$4" points="$5" seed="$6" name
    name="$(basename "$report")"
    [ -f "$report.json" ] && return
    echo "== validate $name against $reference ($points points, evaluation seed $seed)"
    timed "validate $name" "$bin" validate --cohort "$cohort" --reference "$reference" \
        --model "$model" --criteria "$criteria" --points "$points" --seed "$seed" \
        --json "$report.json" --out "$report.html" > "$report.log" 2>&1
}

#!/usr/bin/env bash
# Proves the three-machine deployment (deploy/compose.yaml) end to end:
#
#   engine up → base images → the project's images → the image has `migrate` and `worker` →
#   compose up (postgres, s3, migrate, api with --workers 0, worker-1, worker-2) → a cohort
#   posted to the API container → finished by the worker containers → its GLB downloaded and
#   checked → its meshes found in the S3 bucket → timings → compose down (volumes removed)
#
#   scripts/docker/deployment-check.sh [--no-build]
#     --no-build                skip engine, base-image and image steps (images must exist)
#   AORTAGEN_API_PORT=PORT      published API port (default: a free one)
#   AORTAGEN_KEEP_DEPLOYMENT=1  leave the deployment running afterwards
# Exit status: 0 passed, 1 failed, 2 the image lacks the multi-machine commands.
set -euo pipefail
source "$(dirname "$0")/lib.sh"

IMAGE="${AORTAGEN_IMAGE:-aortagen:latest}"
COMPOSE_FILE="$AORTAGEN_ROOT/deploy/compose.yaml"
PROJECT="aortagen-check"
build=1
case "${1:-}" in
    --no-build) build=0 ;;
    "") ;;
    *) die "usage: $0 [--no-build]" ;;
esac

declare -a timings=()
step() { # step NAME COMMAND...: runs it, records its time
    local name="$1" t0
    shift
    t0="$(now)"
    say "== $name"
    "$@"
    timings+=("$(printf '%-28s %s' "$name" "$(elapsed $(($(now) - t0)))")")
}
print_timings() {
    say "timings:"
    local line
    for line in "${timings[@]}"; do
        printf '    %s\n' "$line" >&2
    done
}

t_start="$(now)"
if [[ $build -eq 1 ]]; then
    step "engine" "$AORTAGEN_ROOT/scripts/docker/engine.sh"
    step "base images" "$AORTAGEN_ROOT/scripts/docker/base-images.sh"
    step "project images" "$AORTAGEN_ROOT/scripts/docker/images.sh"
else
    engine_up || die "no Docker engine answers; run scripts/docker/engine.sh first"
fi

# Compose: the v2 plugin when the client has it, else docker-compose (Debian's 1.29).
if docker compose version >/dev/null 2>&1; then
    compose=(docker compose)
else
    if ! command -v docker-compose >/dev/null; then
        [[ $EUID -eq 0 ]] || die "neither 'docker compose' nor docker-compose is installed"
        say "installing docker-compose with apt"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends docker-compose >/dev/null
    fi
    compose=(docker-compose)
fi
say "compose: ${compose[*]} $("${compose[@]}" version --short 2>/dev/null || true)"
compose+=(-p "$PROJECT" -f "$COMPOSE_FILE")

[[ "$(engine_network)" == bridge ]] \
    || die "the compose deployment needs bridge networking (service names resolve on the project network); this engine runs with --bridge=none"

# --- the image must have the multi-machine commands ----------------------------------------
missing=()
for command in migrate worker; do
    if ! docker run --rm --network none --entrypoint aortagen "$IMAGE" "$command" --help >/dev/null 2>&1; then
        missing+=("$command")
    fi
done
serve_help="$(docker run --rm --network none --entrypoint aortagen "$IMAGE" serve --help 2>/dev/null || true)"
if ! grep -q -- '--workers' <<<"$serve_help"; then
    missing+=("serve --workers")
fi
if [[ ${#missing[@]} -gt 0 ]]; then
    say "STOPPED: the aortagen in $IMAGE has no: ${missing[*]}"
    say "the deployment needs 'aortagen migrate', 'aortagen worker' and 'aortagen serve --workers 0' with PostgreSQL"
    say "(AORTAGEN_DATABASE_URL=postgres://…) and the S3 blob store (AORTAGEN_BLOB_STORE=s3://…); rebuild the image"
    say "from a tree that has them (scripts/docker/images.sh service) and run this again"
    [[ ${#timings[@]} -gt 0 ]] && print_timings
    exit 2
fi
say "$IMAGE has migrate, worker and serve --workers"

# --- up ------------------------------------------------------------------------------------
export AORTAGEN_API_PORT="${AORTAGEN_API_PORT:-$(free_port)}"
export AORTAGEN_API_ADDRESS=127.0.0.1
api="http://127.0.0.1:$AORTAGEN_API_PORT"
out="$(mktemp -d /tmp/aortagen-deployment-check.XXXXXX)"

teardown() {
    local status=$?
    if [[ $status -ne 0 ]]; then
        say "failed; state of the deployment:"
        "${compose[@]}" ps >&2 || true
        "${compose[@]}" logs --no-color --tail 40 >&2 2>&1 || true
    fi
    if [[ "${AORTAGEN_KEEP_DEPLOYMENT:-0}" == 1 ]]; then
        say "left running (AORTAGEN_KEEP_DEPLOYMENT=1): API on $api; stop with: ${compose[*]} down -v"
    else
        say "compose down"
        "${compose[@]}" down -v --remove-orphans >/dev/null 2>&1 || true
    fi
    exit "$status"
}
trap teardown EXIT

# A deployment left by an interrupted run starts from nothing.
"${compose[@]}" down -v --remove-orphans >/dev/null 2>&1 || true
step "compose up" "${compose[@]}" up -d --no-build
step "API answers" wait_http "$api/healthz" 120

for service in migrate api worker-1 worker-2; do
    cid="$("${compose[@]}" ps -a -q "$service")"
    [[ -n "$cid" ]] || die "service $service has no container"
done
migrate_exit="$(docker inspect -f '{{.State.ExitCode}}' "$("${compose[@]}" ps -a -q migrate)")"
[[ "$migrate_exit" == 0 ]] || die "migrate exited with $migrate_exit"
for service in worker-1 worker-2; do
    state="$(docker inspect -f '{{.State.Status}}' "$("${compose[@]}" ps -a -q "$service")")"
    [[ "$state" == running ]] || die "$service is $state, not running"
done
say "migrate finished (exit 0); api, worker-1 and worker-2 running"

# shellcheck disable=SC2034  # read by cohort_roundtrip (lib.sh)
CURL=(curl)
step "cohort round trip" cohort_roundtrip "$api" "$out"

# The meshes went to the object store, not the database.
s3cid="$("${compose[@]}" ps -a -q s3)"
# curl 7.88 signs the query string as written: parameters sorted, "/" encoded.
listing="$(docker exec "$s3cid" sh -c 'curl -fsS -H "x-amz-content-sha256: UNSIGNED-PAYLOAD" --aws-sigv4 aws:amz:us-east-1:s3 --user "$S3_ACCESS_KEY:$S3_SECRET_KEY" "http://127.0.0.1:$S3_PORT/aortagen?list-type=2&prefix=meshes%2F"')"
objects="$(grep -o '<Key>[^<]*</Key>' <<<"$listing" | wc -l)"
[[ "$objects" -gt 0 ]] || die "no object under s3://aortagen/meshes/ after the cohort: $listing"
say "s3://aortagen/meshes/ holds $objects objects"

# Which worker took the cohort's job (informational: the log format is the service's).
for service in api worker-1 worker-2; do
    lines="$("${compose[@]}" logs --no-color "$service" 2>/dev/null | grep -ci "cohort" || true)"
    say "$service: $lines log lines mention a cohort"
done

print_timings
say "PASSED: cohort $COHORT_ID made by the workers, shape $SHAPE_ID's GLB valid, whole check $(elapsed $(($(now) - t_start)))"

#!/usr/bin/env bash
# Checks that the service image serves a cohort on its own (SQLite in the container's /data):
#
#   1. a container with the API published on a free loopback port: POST /v1/cohorts on the
#      bundled model, poll until it succeeded, download a shape's GLB and check it (magic,
#      version 2, length field = file size); the image's HEALTHCHECK must turn healthy;
#   2. the same round trip in a container without any network (--network none), asked from
#      inside it with docker exec: nothing is downloaded at run time.
#
#   scripts/docker/service-check.sh         (image: $AORTAGEN_IMAGE, default aortagen:latest)
# Build the image first: scripts/docker/images.sh service.
set -euo pipefail
source "$(dirname "$0")/lib.sh"

IMAGE="${AORTAGEN_IMAGE:-aortagen:latest}"
engine_up || die "no Docker engine answers; run scripts/docker/engine.sh first"
docker image inspect "$IMAGE" >/dev/null 2>&1 || die "image $IMAGE is missing; run scripts/docker/images.sh service"

out="$(mktemp -d /tmp/aortagen-service-check.XXXXXX)"
containers=()
cleanup() {
    local c
    for c in "${containers[@]}"; do
        docker rm -f -v "$c" >/dev/null 2>&1 || true
    done
}
trap cleanup EXIT

dump_logs() {
    say "last log lines of $1:"
    docker logs --tail 30 "$1" >&2 2>&1 || true
}

# --- 1. published port ---------------------------------------------------------------------
port="$(free_port)"
name="aortagen-service-check-$$"
if [[ "$(engine_network)" == host ]]; then
    # The image's HEALTHCHECK asks port 8080; on the host's network the service has another.
    run_args=(--network host -e "AORTAGEN_BIND=127.0.0.1:$port"
        --health-cmd "curl -fsS http://127.0.0.1:$port/healthz || exit 1")
else
    run_args=(-p "127.0.0.1:$port:8080")
fi
t0="$(now)"
docker run -d --rm --name "$name" "${run_args[@]}" "$IMAGE" >/dev/null
containers+=("$name")
say "started $name from $IMAGE on 127.0.0.1:$port"
wait_http "http://127.0.0.1:$port/healthz" 120 || { dump_logs "$name"; die "the API did not answer /healthz"; }
say "/healthz answered $(($(now) - t0)) s after docker run"
# shellcheck disable=SC2034  # read by cohort_roundtrip (lib.sh)
CURL=(curl)
cohort_roundtrip "http://127.0.0.1:$port" "$out/published" || { dump_logs "$name"; die "cohort round trip through the published port failed"; }
published_seconds="$COHORT_SECONDS"

# The image's HEALTHCHECK (every 30 s after a 10 s start period) must report healthy.
for _ in $(seq 1 60); do
    health="$(docker inspect -f '{{.State.Health.Status}}' "$name")"
    [[ "$health" == starting ]] || break
    sleep 1
done
[[ "$health" == healthy ]] || { dump_logs "$name"; die "the image's HEALTHCHECK reports '$health'"; }
say "image HEALTHCHECK: $health"
docker stop "$name" >/dev/null

# --- 2. no network -------------------------------------------------------------------------
name="aortagen-service-check-offline-$$"
docker run -d --rm --name "$name" --network none "$IMAGE" >/dev/null
containers+=("$name")
say "started $name with --network none"
for _ in $(seq 1 120); do
    docker exec "$name" curl -fsS -o /dev/null --max-time 5 http://127.0.0.1:8080/healthz 2>/dev/null && break
    sleep 1
done
# shellcheck disable=SC2034  # read by cohort_roundtrip (lib.sh)
CURL=(docker exec -i "$name" curl)
cohort_roundtrip "http://127.0.0.1:8080" "$out/offline" || { dump_logs "$name"; die "cohort round trip without network failed"; }
docker stop "$name" >/dev/null

say "PASSED: $IMAGE serves cohorts (published port: cohort in ${published_seconds} s; without network: in ${COHORT_SECONDS} s); GLBs in $out"

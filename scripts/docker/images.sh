#!/usr/bin/env bash
# Builds the project's images with BuildKit (the base images must be there: base-images.sh):
#
#   service    aortagen:latest           Dockerfile (context: the repository)
#   postgres   aortagen-postgres:15      deploy/postgres.Dockerfile (context: deploy/)
#   s3         aortagen-s3:latest        deploy/s3.Dockerfile (context: deploy/)
#
#   scripts/docker/images.sh [service|postgres|s3 ...]     (default: all three)
# Each build's log goes to $AORTAGEN_DOCKER_HOME/build-NAME.log and its time to
# $AORTAGEN_DOCKER_HOME/timings.log.
set -euo pipefail
source "$(dirname "$0")/lib.sh"

SERVICE_IMAGE="${AORTAGEN_IMAGE:-aortagen:latest}"
POSTGRES_IMAGE="${AORTAGEN_POSTGRES_IMAGE:-aortagen-postgres:15}"
S3_IMAGE="${AORTAGEN_S3_IMAGE:-aortagen-s3:latest}"

engine_up || die "no Docker engine answers; run scripts/docker/engine.sh first"
for base in debian:bookworm-slim rust:1.95-slim-bookworm; do
    docker image inspect "$base" >/dev/null 2>&1 || die "base image $base is missing; run scripts/docker/base-images.sh first"
done

build_one() {
    local name="$1" tag dockerfile context
    case "$name" in
        service) tag="$SERVICE_IMAGE" dockerfile="$AORTAGEN_ROOT/Dockerfile" context="$AORTAGEN_ROOT" ;;
        postgres) tag="$POSTGRES_IMAGE" dockerfile="$AORTAGEN_ROOT/deploy/postgres.Dockerfile" context="$AORTAGEN_ROOT/deploy" ;;
        s3) tag="$S3_IMAGE" dockerfile="$AORTAGEN_ROOT/deploy/s3.Dockerfile" context="$AORTAGEN_ROOT/deploy" ;;
        *) die "unknown image '$name' (service, postgres or s3)" ;;
    esac
    local logfile="$AORTAGEN_DOCKER_HOME/build-$name.log" t0 seconds
    mkdir -p "$AORTAGEN_DOCKER_HOME"
    say "$name: building $tag (log: $logfile)"
    t0="$(now)"
    if ! docker_build "$tag" "$dockerfile" "$context" >"$logfile" 2>&1; then
        tail -n 30 "$logfile" >&2
        die "$name: building $tag failed; see $logfile"
    fi
    seconds=$(($(now) - t0))
    printf '%s\t%s\t%s\t%ss\n' "$(date -Is)" "$name" "$tag" "$seconds" >>"$AORTAGEN_DOCKER_HOME/timings.log"
    say "$name: $tag built in $(elapsed "$seconds") ($(docker image inspect -f '{{.Size}}' "$tag" | numfmt --to=iec))"
}

names=("$@")
[[ ${#names[@]} -gt 0 ]] || names=(postgres s3 service)
for name in "${names[@]}"; do
    build_one "$name"
done

# Shared helpers of the scripts in scripts/docker/ (sourced, not run).
# shellcheck shell=bash
# shellcheck disable=SC2034  # AORTAGEN_ROOT, CURL, COHORT_ID, SHAPE_ID are for the callers

# The repository root, whichever script sourced this file.
AORTAGEN_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
# Where the engine keeps its data, log and settings when engine.sh starts it.
AORTAGEN_DOCKER_HOME="${AORTAGEN_DOCKER_HOME:-$HOME/.cache/aortagen-docker}"
# Written by engine.sh: the network mode builds and containers must use (bridge or host).
AORTAGEN_ENGINE_ENV="$AORTAGEN_DOCKER_HOME/engine.env"

say() { printf '[%s] %s\n' "$(basename "$0")" "$*" >&2; }
die() { say "error: $*"; exit 1; }

# Seconds since the epoch, for timings.
now() { date +%s; }
# "12m34s" for a number of seconds.
elapsed() { printf '%dm%02ds' "$(($1 / 60))" "$(($1 % 60))"; }

engine_up() { docker info >/dev/null 2>&1; }

# The network mode engine.sh recorded (bridge when it did not record one).
engine_network() {
    local mode=bridge
    if [[ -r "$AORTAGEN_ENGINE_ENV" ]]; then
        mode="$(sed -n 's/^AORTAGEN_DOCKER_NETWORK=//p' "$AORTAGEN_ENGINE_ENV")"
    fi
    printf '%s\n' "${mode:-bridge}"
}

# A docker client that builds with BuildKit (RUN --mount needs it). Docker 23 and later
# build through the buildx plugin; without the plugin they refuse DOCKER_BUILDKIT=1.
# Debian's docker.io (20.10) client has BuildKit built in, so it is used then.
build_client() {
    if docker buildx version >/dev/null 2>&1; then
        printf 'docker\n'
        return
    fi
    local candidate version
    for candidate in /usr/bin/docker "$(command -v docker)"; do
        [[ -x "$candidate" ]] || continue
        version="$("$candidate" version --format '{{.Client.Version}}' 2>/dev/null || true)"
        if [[ "$version" == 18.* || "$version" == 19.* || "$version" == 20.* ]]; then
            printf '%s\n' "$candidate"
            return
        fi
    done
    die "no docker client here can build with BuildKit: install the buildx plugin, or Debian's docker.io (its 20.10 client has BuildKit built in)"
}

# docker build with BuildKit, in the network mode the engine supports.
# Usage: docker_build TAG DOCKERFILE CONTEXT [extra docker build arguments...]
docker_build() {
    local tag="$1" dockerfile="$2" context="$3"
    shift 3
    local client network
    client="$(build_client)"
    network="$(engine_network)"
    local args=(build --progress=plain -t "$tag" -f "$dockerfile")
    if [[ "$network" == host ]]; then
        args+=(--network host)
    fi
    DOCKER_BUILDKIT=1 "$client" "${args[@]}" "$@" "$context"
}

# Extra `docker run` arguments for the engine's network mode.
run_network_args() {
    if [[ "$(engine_network)" == host ]]; then
        printf -- '--network=host\n'
    fi
}

# Checks that FILE is a binary glTF 2.0 container: magic "glTF", version 2, and a length
# field equal to the file's size. Prints what it found.
check_glb() {
    local file="$1" size magic version length
    [[ -s "$file" ]] || { say "GLB check: $file is missing or empty"; return 1; }
    size="$(stat -c %s "$file")"
    magic="$(head -c 4 "$file")"
    version="$(od -An -t u4 -j 4 -N 4 --endian=little "$file" | tr -d ' ')"
    length="$(od -An -t u4 -j 8 -N 4 --endian=little "$file" | tr -d ' ')"
    if [[ "$magic" != glTF || "$version" != 2 || "$length" != "$size" ]]; then
        say "GLB check failed for $file: magic '$magic', version $version, length field $length, file size $size"
        return 1
    fi
    say "GLB check passed for $file: magic glTF, version 2, length $length = file size"
}

# JSON field of a document on stdin, by a Python expression on `d` (python3 on the host).
json_get() { python3 -c 'import json, sys; d = json.load(sys.stdin); v = eval(sys.argv[1]); print("" if v is None else v)' "$1"; }

# Waits until URL answers 2xx, at most SECONDS. Usage: wait_http URL SECONDS
wait_http() {
    local url="$1" limit="$2" start
    start="$(now)"
    until curl -fsS -o /dev/null --max-time 5 "$url" 2>/dev/null; do
        if (($(now) - start >= limit)); then
            say "$url did not answer within ${limit} s"
            return 1
        fi
        sleep 1
    done
}

# How cohort_roundtrip reaches the API: a command that takes curl's arguments. Default: the
# host's curl; e.g. (docker exec -i CONTAINER curl) to ask from inside a container.
CURL=(curl)

# The cohort round trip against a running API: POST /v1/cohorts (bundled model "default",
# 2 shapes of arity 2 at resolution 32), poll until the cohort succeeded, download the first
# shape's GLB into DIR and check it. Sets COHORT_ID, SHAPE_ID and COHORT_SECONDS.
# Usage: cohort_roundtrip BASE_URL DIR [TIMEOUT_SECONDS]   (prints the timings)
cohort_roundtrip() {
    local base="$1" dir="$2" limit="${3:-900}"
    local request='{"model_id":"default","count":2,"arity":2,"weighting":"dirichlet","seed":7,"resolution":32}'
    local t0 body id status progress shape_id glb
    mkdir -p "$dir"
    t0="$(now)"
    body="$("${CURL[@]}" -fsS --max-time 30 -X POST "$base/v1/cohorts" -H 'content-type: application/json' -d "$request")" \
        || { say "POST $base/v1/cohorts failed"; return 1; }
    id="$(json_get 'd["id"]' <<<"$body")"
    say "cohort $id accepted: $request"
    while :; do
        body="$("${CURL[@]}" -fsS --max-time 10 "$base/v1/cohorts/$id")" || { say "GET /v1/cohorts/$id failed"; return 1; }
        status="$(json_get 'd["status"]' <<<"$body")"
        progress="$(json_get '"%s/%s" % (d["progress"]["done"], d["progress"]["total"])' <<<"$body" 2>/dev/null || true)"
        case "$status" in
            succeeded) break ;;
            failed | cancelled)
                say "cohort $id $status: $(json_get 'd.get("error")' <<<"$body")"
                return 1
                ;;
        esac
        if (($(now) - t0 > limit)); then
            say "cohort $id still $status (progress $progress) after ${limit} s"
            return 1
        fi
        sleep 1
    done
    COHORT_ID="$id"
    COHORT_SECONDS=$(($(now) - t0))
    say "cohort $id succeeded in ${COHORT_SECONDS} s (shapes $progress)"
    body="$("${CURL[@]}" -fsS --max-time 10 "$base/v1/cohorts/$id/shapes")"
    shape_id="$(json_get 'd["items"][0]["id"]' <<<"$body")"
    SHAPE_ID="$shape_id"
    glb="$dir/shape-$shape_id.glb"
    "${CURL[@]}" -fsS --max-time 60 "$base/v1/shapes/$shape_id/mesh" >"$glb" \
        || { say "GET /v1/shapes/$shape_id/mesh failed"; return 1; }
    say "shape $shape_id: GLB downloaded, $(stat -c %s "$glb") bytes"
    check_glb "$glb"
    say "timings: cohort generated in ${COHORT_SECONDS} s; POST to validated GLB $(($(now) - t0)) s"
}

# A free TCP port on the loopback interface.
free_port() { python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }

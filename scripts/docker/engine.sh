#!/usr/bin/env bash
# Makes sure a Docker engine answers on this machine.
#
#   scripts/docker/engine.sh          start one if none answers (installs Debian's docker.io when missing)
#   scripts/docker/engine.sh stop     stop the engine this script started
#
# When no engine answers, dockerd is started in the background (as root) with its data under
# $AORTAGEN_DOCKER_HOME (default ~/.cache/aortagen-docker): log in dockerd.log, pid in
# dockerd.pid. Storage drivers are tried in the order overlay2, fuse-overlayfs, vfs; bridge
# networking first, then --iptables=false --bridge=none (containers and builds then need
# --network host). The mode that worked is written to engine.env for the other scripts.
# AORTAGEN_DOCKER_NETWORK=host skips the bridge attempt.
set -euo pipefail
source "$(dirname "$0")/lib.sh"

pidfile="$AORTAGEN_DOCKER_HOME/dockerd.pid"
log="$AORTAGEN_DOCKER_HOME/dockerd.log"

if [[ "${1:-}" == stop ]]; then
    if [[ -s "$pidfile" ]] && kill -0 "$(cat "$pidfile")" 2>/dev/null; then
        pid="$(cat "$pidfile")"
        say "stopping dockerd (pid $pid)"
        kill "$pid"
        for _ in $(seq 1 30); do
            kill -0 "$pid" 2>/dev/null || { say "dockerd stopped"; exit 0; }
            sleep 1
        done
        die "dockerd (pid $pid) still runs 30 s after SIGTERM; see $log"
    fi
    say "no dockerd started by this script is running (no live pid in $pidfile)"
    exit 0
fi
[[ $# -eq 0 ]] || die "usage: $0 [stop]"

describe_engine() {
    docker info --format 'server {{.ServerVersion}}, storage driver {{.Driver}}, {{.NCPU}} CPUs' 2>/dev/null
}

if engine_up; then
    say "a Docker engine already answers ($(describe_engine)); nothing started"
    if [[ ! -s "$AORTAGEN_ENGINE_ENV" ]]; then
        mkdir -p "$AORTAGEN_DOCKER_HOME"
        printf 'AORTAGEN_DOCKER_NETWORK=%s\n' "${AORTAGEN_DOCKER_NETWORK:-bridge}" >"$AORTAGEN_ENGINE_ENV"
    fi
    say "network mode for builds and containers: $(engine_network)"
    exit 0
fi

[[ $EUID -eq 0 ]] || die "no Docker engine answers and starting dockerd needs root (run this script as root)"

# --- packages ------------------------------------------------------------------------------
apt_updated=0
apt_install() {
    if [[ $apt_updated -eq 0 ]]; then
        say "apt-get update"
        apt-get update -qq
        apt_updated=1
    fi
    say "installing with apt: $*"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$@" >/dev/null
}
missing=()
command -v dockerd >/dev/null || missing+=(docker.io)
command -v iptables >/dev/null || missing+=(iptables)
command -v ip >/dev/null || missing+=(iproute2)
if [[ ${#missing[@]} -gt 0 ]]; then
    apt_install "${missing[@]}"
else
    say "dockerd, iptables and ip are installed ($(dockerd --version))"
fi

# --- start ---------------------------------------------------------------------------------
mkdir -p "$AORTAGEN_DOCKER_HOME/data"

# Containers get the MTU of the interface of the default route: a bridge at 1500 behind a
# smaller link loses large packets (TLS downloads in builds hang).
mtu=""
dev="$(ip route show default 2>/dev/null | awk '{for (i = 1; i < NF; i++) if ($i == "dev") { print $(i + 1); exit }}')"
if [[ -n "$dev" && -r "/sys/class/net/$dev/mtu" ]]; then
    mtu="$(cat "/sys/class/net/$dev/mtu")"
fi

started_pid=""
# try_start DRIVER NETWORK: starts dockerd and waits up to 60 s for `docker info`.
try_start() {
    local driver="$1" network="$2"
    local args=(--data-root "$AORTAGEN_DOCKER_HOME/data" --pidfile "$pidfile" --storage-driver "$driver")
    [[ -n "$mtu" ]] && args+=(--mtu "$mtu")
    [[ "$network" == host ]] && args+=(--iptables=false --ip6tables=false --bridge=none)
    if [[ "$driver" == fuse-overlayfs ]] && ! command -v fuse-overlayfs >/dev/null; then
        apt_install fuse-overlayfs
    fi
    say "starting dockerd: storage driver $driver, network $network${mtu:+, MTU $mtu} (log: $log)"
    printf '\n===== %s dockerd %s\n' "$(date -Is)" "${args[*]}" >>"$log"
    setsid dockerd "${args[@]}" >>"$log" 2>&1 </dev/null &
    local pid=$!
    for _ in $(seq 1 60); do
        if ! kill -0 "$pid" 2>/dev/null; then
            say "dockerd exited during start-up; its last error lines:"
            grep -E 'level=(error|fatal)|failed to start daemon' "$log" | tail -n 5 >&2 || tail -n 5 "$log" >&2
            return 1
        fi
        if engine_up; then
            local actual
            actual="$(docker info --format '{{.Driver}}')"
            if [[ "$actual" != "$driver" ]]; then
                say "dockerd answered with storage driver $actual instead of $driver; stopping it"
                kill "$pid"
                wait "$pid" 2>/dev/null || true
                return 1
            fi
            started_pid="$pid"
            return 0
        fi
        sleep 1
    done
    say "dockerd did not answer within 60 s; stopping it"
    kill "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
    return 1
}

networks=(bridge host)
[[ "${AORTAGEN_DOCKER_NETWORK:-}" == host ]] && networks=(host)
for network in "${networks[@]}"; do
    for driver in overlay2 fuse-overlayfs vfs; do
        if try_start "$driver" "$network"; then
            printf 'AORTAGEN_DOCKER_NETWORK=%s\nAORTAGEN_DOCKER_STORAGE=%s\n' "$network" "$driver" >"$AORTAGEN_ENGINE_ENV"
            say "dockerd started (pid $started_pid): $(describe_engine), network mode $network"
            say "data root $AORTAGEN_DOCKER_HOME/data; stop it with: $0 stop"
            if [[ "$network" == host && "${AORTAGEN_DOCKER_NETWORK:-}" == host ]]; then
                say "no bridge (AORTAGEN_DOCKER_NETWORK=host): builds and containers use --network host"
            elif [[ "$network" == host ]]; then
                say "bridge networking failed here: builds and containers use --network host"
            fi
            exit 0
        fi
    done
done
die "dockerd could not start with any storage driver (overlay2, fuse-overlayfs, vfs) or network mode (bridge, host); see $log"

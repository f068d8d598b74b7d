#!/usr/bin/env bash
# A throwaway PostgreSQL server for the tests, started from the machine's server binaries
# (Debian's postgresql package, /usr/lib/postgresql/<version>/bin). PostgreSQL refuses to run
# as root, so as root it runs as a system user (`postgres` when present, else one created).
#
#   tests/support/postgres.sh start DIR   initialise DIR, start the server, print its URL
#   tests/support/postgres.sh stop DIR    stop it and remove DIR
#
# The server listens on 127.0.0.1 on a free port with trust authentication for the
# `aortagen` superuser; durability is off (fsync, synchronous_commit): the data is thrown
# away after the tests.
set -euo pipefail

command=${1:?usage: postgres.sh start|stop DIR}
dir=${2:?usage: postgres.sh start|stop DIR}

bin_dir() {
    local found
    found=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -n 1 || true)
    if [[ -z "$found" ]]; then
        echo "postgres.sh: no PostgreSQL server binaries under /usr/lib/postgresql;" \
             "installing Debian's postgresql package" >&2
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q postgresql >&2
        found=$(ls -d /usr/lib/postgresql/*/bin | sort -V | tail -n 1)
    fi
    echo "$found"
}

# Runs a command as the server's user (as-is when not root).
as_server_user() {
    if [[ $(id -u) -ne 0 ]]; then
        "$@"
    else
        runuser -u "$server_user" -- "$@"
    fi
}

server_user=postgres
if [[ $(id -u) -eq 0 ]] && ! id "$server_user" >/dev/null 2>&1; then
    server_user=aortagen-pg
    id "$server_user" >/dev/null 2>&1 || useradd --system --no-create-home "$server_user"
fi

case "$command" in
start)
    bin=$(bin_dir)
    mkdir -p "$dir"
    [[ $(id -u) -eq 0 ]] && chown "$server_user" "$dir"
    as_server_user "$bin/initdb" -D "$dir/data" -A trust -U aortagen --no-sync \
        --encoding UTF8 --locale C >"$dir/initdb.log" 2>&1 \
        || { cat "$dir/initdb.log" >&2; exit 1; }
    port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
    as_server_user "$bin/pg_ctl" -D "$dir/data" -l "$dir/server.log" -w -t 60 \
        -o "-p $port -k $dir -c listen_addresses=127.0.0.1 -c max_connections=300 -c fsync=off -c synchronous_commit=off -c full_page_writes=off" \
        start >&2 || { cat "$dir/server.log" >&2; exit 1; }
    echo "$port" >"$dir/port"
    echo "postgres://aortagen@127.0.0.1:$port/postgres"
    ;;
stop)
    bin=$(bin_dir)
    if [[ -d "$dir/data" ]]; then
        as_server_user "$bin/pg_ctl" -D "$dir/data" -m fast -w stop >&2 || true
    fi
    rm -rf "$dir"
    ;;
*)
    echo "usage: postgres.sh start|stop DIR" >&2
    exit 2
    ;;
esac

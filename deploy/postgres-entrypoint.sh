#!/usr/bin/env bash
# Entrypoint of deploy/postgres.Dockerfile. On the first start (no PG_VERSION in $PGDATA) it
# creates the cluster with superuser $POSTGRES_USER (default postgres) and password
# $POSTGRES_PASSWORD (required), and database $POSTGRES_DB (default: the user's name).
# Then it runs the server, listening on every address of the container.
set -euo pipefail

say() { printf '[postgres-entrypoint] %s\n' "$*" >&2; }

if [[ "${1:-}" != postgres ]]; then
    exec "$@"
fi
shift

user="${POSTGRES_USER:-postgres}"
db="${POSTGRES_DB:-$user}"

if [[ ! -s "$PGDATA/PG_VERSION" ]]; then
    if [[ -z "${POSTGRES_PASSWORD:-}" ]]; then
        say "error: the data directory $PGDATA is empty and POSTGRES_PASSWORD is not set"
        exit 1
    fi
    say "initialising a new cluster in $PGDATA (superuser $user, database $db)"
    pwfile="$(mktemp)"
    printf '%s\n' "$POSTGRES_PASSWORD" >"$pwfile"
    initdb --pgdata="$PGDATA" --username="$user" --pwfile="$pwfile" --encoding=UTF8 --locale=C.UTF-8 \
        --auth-local=trust --auth-host=scram-sha-256 >/dev/null
    rm -f "$pwfile"
    # Clients on other machines (containers) authenticate with the password.
    printf 'host all all all scram-sha-256\n' >>"$PGDATA/pg_hba.conf"
    if [[ "$db" != postgres ]]; then
        pg_ctl --pgdata="$PGDATA" --options="-c listen_addresses=''" --wait --silent start
        # The user's own database may already exist when the user is called postgres.
        if ! psql --username="$user" --dbname=postgres --tuples-only --no-align \
            --command="SELECT 1 FROM pg_database WHERE datname = '${db//\'/\'\'}'" | grep -q 1; then
            createdb --username="$user" --owner="$user" "$db"
        fi
        pg_ctl --pgdata="$PGDATA" --mode=fast --wait --silent stop
    fi
    say "cluster ready"
fi

exec postgres -D "$PGDATA" -c listen_addresses='*' "$@"

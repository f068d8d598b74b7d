#!/usr/bin/env bash
# Entrypoint of deploy/s3.Dockerfile: creates the buckets named in S3_BUCKETS (comma or space
# separated; s3s-fs keeps a bucket as a directory of /data), then serves /data on S3_PORT with
# the key pair S3_ACCESS_KEY / S3_SECRET_KEY. Arguments are passed on to s3s-fs.
set -euo pipefail

say() { printf '[s3-entrypoint] %s\n' "$*" >&2; }

if [[ -z "${S3_ACCESS_KEY:-}" || -z "${S3_SECRET_KEY:-}" ]]; then
    say "error: set S3_ACCESS_KEY and S3_SECRET_KEY (the key pair clients sign requests with)"
    exit 1
fi

for bucket in ${S3_BUCKETS//,/ }; do
    if [[ ! "$bucket" =~ ^[a-z0-9][a-z0-9.-]{1,61}[a-z0-9]$ ]]; then
        say "error: '$bucket' in S3_BUCKETS is not a valid bucket name"
        exit 1
    fi
    if [[ ! -d "/data/$bucket" ]]; then
        mkdir "/data/$bucket"
        say "created bucket $bucket"
    fi
done

exec s3s-fs --host 0.0.0.0 --port "${S3_PORT:-8014}" \
    --access-key "$S3_ACCESS_KEY" --secret-key "$S3_SECRET_KEY" "$@" /data

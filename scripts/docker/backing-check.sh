#!/usr/bin/env bash
# Checks the deployment's backing services on their own, from their images:
#
#   postgres (aortagen-postgres:15)  turns healthy, pg_isready answers, a password login over
#                                    TCP runs a query and a wrong password is refused
#   s3 (aortagen-s3:latest)          turns healthy, and SigV4-signed requests (curl --aws-sigv4)
#                                    do ListBuckets, CreateBucket, PutObject, GetObject (same
#                                    bytes), ListObjectsV2 and DeleteObject; unsigned ones are refused
#
#   scripts/docker/backing-check.sh       (build the images first: scripts/docker/images.sh postgres s3)
set -euo pipefail
source "$(dirname "$0")/lib.sh"

POSTGRES_IMAGE="${AORTAGEN_POSTGRES_IMAGE:-aortagen-postgres:15}"
S3_IMAGE="${AORTAGEN_S3_IMAGE:-aortagen-s3:latest}"
engine_up || die "no Docker engine answers; run scripts/docker/engine.sh first"
for image in "$POSTGRES_IMAGE" "$S3_IMAGE"; do
    docker image inspect "$image" >/dev/null 2>&1 || die "image $image is missing; run scripts/docker/images.sh postgres s3"
done

suffix="$$"
pg="aortagen-pg-check-$suffix"
s3="aortagen-s3-check-$suffix"
work="$(mktemp -d /tmp/aortagen-backing-check.XXXXXX)"
cleanup() {
    docker rm -f -v "$pg" "$s3" >/dev/null 2>&1 || true
    rm -rf "$work"
}
trap cleanup EXIT

wait_healthy() {
    local container="$1" limit="$2" start health
    start="$(now)"
    while :; do
        health="$(docker inspect -f '{{.State.Health.Status}}' "$container" 2>/dev/null || echo gone)"
        [[ "$health" == healthy ]] && { say "$container healthy after $(($(now) - start)) s"; return 0; }
        if [[ "$health" == unhealthy || "$health" == gone ]] || (($(now) - start > limit)); then
            say "$container is $health; its last log lines:"
            docker logs --tail 30 "$container" >&2 2>&1 || true
            return 1
        fi
        sleep 1
    done
}

host_mode=0
[[ "$(engine_network)" == host ]] && host_mode=1

# --- PostgreSQL ----------------------------------------------------------------------------
password="check-$(od -An -N8 -tx8 /dev/urandom | tr -d ' ')"
pg_args=(-e POSTGRES_USER=aortagen -e "POSTGRES_PASSWORD=$password" -e POSTGRES_DB=aortagen)
pg_port=5432
if [[ $host_mode -eq 1 ]]; then
    pg_port="$(free_port)"
    pg_args+=(--network host --health-cmd "pg_isready -h 127.0.0.1 -p $pg_port -q")
    docker run -d --name "$pg" "${pg_args[@]}" "$POSTGRES_IMAGE" postgres -c "port=$pg_port" >/dev/null
else
    docker run -d --name "$pg" "${pg_args[@]}" "$POSTGRES_IMAGE" >/dev/null
fi
wait_healthy "$pg" 90 || die "PostgreSQL did not turn healthy"
say "pg_isready: $(docker exec "$pg" pg_isready -h 127.0.0.1 -p "$pg_port" -U aortagen -d aortagen)"
# Over TCP with the password (scram-sha-256), as the service will connect.
answer="$(docker exec -e "PGPASSWORD=$password" "$pg" psql -h 127.0.0.1 -p "$pg_port" -U aortagen -d aortagen -tAc \
    "SELECT current_user || ' ' || current_database() || ' ' || current_setting('server_version')")"
[[ "$answer" == "aortagen aortagen 15."* ]] || die "unexpected answer from PostgreSQL: $answer"
say "PostgreSQL password login over TCP: $answer"
if docker exec -e PGPASSWORD=wrong "$pg" psql -h 127.0.0.1 -p "$pg_port" -U aortagen -d aortagen -tAc 'SELECT 1' >/dev/null 2>&1; then
    die "PostgreSQL accepted a wrong password"
fi
say "PostgreSQL refused a wrong password"

# --- S3 ------------------------------------------------------------------------------------
access="check-access"
secret="check-secret-$(od -An -N8 -tx8 /dev/urandom | tr -d ' ')"
s3_port="$(free_port)"
if [[ $host_mode -eq 1 ]]; then
    docker run -d --name "$s3" --network host -e "S3_PORT=$s3_port" -e "S3_ACCESS_KEY=$access" -e "S3_SECRET_KEY=$secret" \
        -e S3_BUCKETS=aortagen "$S3_IMAGE" >/dev/null
else
    docker run -d --name "$s3" -p "127.0.0.1:$s3_port:8014" -e "S3_ACCESS_KEY=$access" -e "S3_SECRET_KEY=$secret" \
        -e S3_BUCKETS=aortagen "$S3_IMAGE" >/dev/null
fi
wait_healthy "$s3" 60 || die "the S3 server did not turn healthy"
endpoint="http://127.0.0.1:$s3_port"
# curl 7.88 sends no payload hash of its own; s3s-fs wants the header (UNSIGNED-PAYLOAD is valid).
s3curl() { curl -fsS --max-time 10 -H 'x-amz-content-sha256: UNSIGNED-PAYLOAD' --aws-sigv4 "aws:amz:us-east-1:s3" --user "$access:$secret" "$@"; }

status="$(curl -s -o /dev/null -w '%{http_code}' "$endpoint/")"
[[ "$status" == 403 || "$status" == 401 ]] || die "an unsigned ListBuckets got HTTP $status, not 401/403"
say "S3 unsigned request refused (HTTP $status)"
buckets="$(s3curl "$endpoint/")"
grep -q '<Name>aortagen</Name>' <<<"$buckets" || die "ListBuckets does not list the bucket created from S3_BUCKETS: $buckets"
say "S3 ListBuckets lists aortagen (created at start from S3_BUCKETS)"
s3curl -X PUT "$endpoint/aortagen-check" -o /dev/null
say "S3 CreateBucket aortagen-check"
head -c 100000 /dev/urandom >"$work/object"
s3curl -X PUT -H 'content-type: model/gltf-binary' --data-binary "@$work/object" "$endpoint/aortagen/meshes/check/object.glb" -o /dev/null
s3curl "$endpoint/aortagen/meshes/check/object.glb" -o "$work/back"
cmp -s "$work/object" "$work/back" || die "GetObject returned other bytes than PutObject stored"
say "S3 PutObject + GetObject: 100000 bytes back unchanged"
# curl 7.88 signs the query string as written: parameters sorted, "/" encoded.
listing="$(s3curl "$endpoint/aortagen?list-type=2&prefix=meshes%2F")"
grep -q '<Key>meshes/check/object.glb</Key>' <<<"$listing" || die "ListObjectsV2 does not list the object: $listing"
say "S3 ListObjectsV2 lists meshes/check/object.glb"
s3curl -X DELETE "$endpoint/aortagen/meshes/check/object.glb" -o /dev/null
status="$(curl -s -o /dev/null -w '%{http_code}' -H 'x-amz-content-sha256: UNSIGNED-PAYLOAD' --aws-sigv4 "aws:amz:us-east-1:s3" --user "$access:$secret" "$endpoint/aortagen/meshes/check/object.glb")"
[[ "$status" == 404 ]] || die "a deleted object answered HTTP $status, not 404"
say "S3 DeleteObject: the object is gone (404)"

say "PASSED: PostgreSQL 15 and the S3 server answer as the deployment needs"

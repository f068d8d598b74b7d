# An S3-compatible object store for the deployment and its tests: s3s-fs from crates.io, which
# keeps each bucket as a directory under /data (a volume) and each object as a file.
# Build (context: deploy/): docker build -t aortagen-s3 -f deploy/s3.Dockerfile deploy
# Run:   docker run -e S3_ACCESS_KEY=… -e S3_SECRET_KEY=… [-e S3_BUCKETS=aortagen]
#        -v s3data:/data -p 8014:8014 aortagen-s3
# Path-style addressing (http://host:8014/BUCKET/KEY); any region name is accepted.

# --- build: cargo install from crates.io (0.14 is the last release for Rust 1.95) ---
FROM rust:1.95-slim-bookworm AS build
ARG S3S_FS_VERSION=0.14.1
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    cargo install --locked --features binary --root /opt/s3s-fs "s3s-fs@${S3S_FS_VERSION}"

# --- runtime ---
FROM debian:bookworm-slim
# curl signs the health check's ListBuckets request (--aws-sigv4; curl 7.88 sends no payload
# hash of its own, which s3s-fs requires: the check sends x-amz-content-sha256 itself).
RUN apt-get update && apt-get install -y --no-install-recommends curl \
    && rm -rf /var/lib/apt/lists/* \
    && useradd --system --uid 10002 --home /data s3 \
    && mkdir -p /data && chown s3 /data
COPY --from=build /opt/s3s-fs/bin/s3s-fs /usr/local/bin/s3s-fs
COPY s3-entrypoint.sh /usr/local/bin/s3-entrypoint.sh
USER s3
WORKDIR /data
VOLUME /data
ENV S3_PORT=8014 \
    S3_BUCKETS="" \
    RUST_LOG=s3s_fs=info
EXPOSE 8014
HEALTHCHECK --interval=5s --timeout=3s --start-period=10s --retries=5 \
    CMD curl -fsS -o /dev/null -H "x-amz-content-sha256: UNSIGNED-PAYLOAD" --aws-sigv4 aws:amz:us-east-1:s3 --user "$S3_ACCESS_KEY:$S3_SECRET_KEY" \
        "http://127.0.0.1:$S3_PORT/" || exit 1
ENTRYPOINT ["s3-entrypoint.sh"]

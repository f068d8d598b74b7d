# aortagen cohort service.
# Build: docker build -t aortagen .
# Run:   docker run -p 8080:8080 -v aortagen-data:/data aortagen
# Needs network only for crates (cargo fetch); nothing is downloaded at run time.

# --- build (BuildKit cache mounts keep crates and artefacts between builds) ---
FROM rust:1.95-slim-bookworm AS build
WORKDIR /src
# The whole context, including migrations/ (embedded by sqlx::migrate!() at compile time).
COPY . .
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo fetch --locked \
    && cargo build --release --locked --offline --bin aortagen \
    && cp target/release/aortagen /aortagen \
    && mkdir -p models

# --- runtime: the binary, the bundled model, a non-root user, a volume for the database ---
FROM debian:bookworm-slim
RUN apt-get update && apt-get install -y --no-install-recommends curl ca-certificates \
    && rm -rf /var/lib/apt/lists/* \
    && useradd --system --uid 10001 --home /data aortagen \
    && mkdir -p /data /opt/aortagen && chown aortagen /data
COPY --from=build /aortagen /usr/local/bin/aortagen
COPY --from=build /src/models /opt/aortagen/models
USER aortagen
WORKDIR /data
VOLUME /data
ENV AORTAGEN_BIND=0.0.0.0:8080 \
    AORTAGEN_DATABASE_URL=sqlite:///data/aortagen.db \
    AORTAGEN_MODELS_DIR=/opt/aortagen/models \
    AORTAGEN_LOG_JSON=true
EXPOSE 8080
HEALTHCHECK --interval=30s --timeout=3s --start-period=10s --retries=3 \
    CMD curl -fsS http://127.0.0.1:8080/healthz || exit 1
ENTRYPOINT ["aortagen"]
CMD ["serve"]

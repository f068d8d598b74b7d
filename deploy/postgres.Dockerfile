# PostgreSQL 15 from Debian's packages, for the multi-machine deployment (deploy/compose.yaml).
# Build (context: deploy/): docker build -t aortagen-postgres:15 -f deploy/postgres.Dockerfile deploy
# Run:   docker run -e POSTGRES_PASSWORD=… [-e POSTGRES_USER=aortagen -e POSTGRES_DB=aortagen]
#        -v pgdata:/var/lib/postgresql/data aortagen-postgres:15
# The first start creates the cluster in the empty data volume (scram-sha-256 password
# authentication over TCP, trust over the container's own socket) and the database.
FROM debian:bookworm-slim

# No "main" cluster at install time: the entrypoint creates one in the data volume.
RUN mkdir -p /etc/postgresql-common/createcluster.d \
    && echo 'create_main_cluster = false' >/etc/postgresql-common/createcluster.d/no-main-cluster.conf \
    && apt-get update \
    && apt-get install -y --no-install-recommends postgresql-15 \
    && rm -rf /var/lib/apt/lists/* \
    && mkdir -p /var/lib/postgresql/data /var/run/postgresql \
    && chown -R postgres:postgres /var/lib/postgresql /var/run/postgresql \
    && chmod 700 /var/lib/postgresql/data \
    && chmod 2777 /var/run/postgresql

COPY postgres-entrypoint.sh /usr/local/bin/postgres-entrypoint.sh

ENV PATH=/usr/lib/postgresql/15/bin:$PATH \
    PGDATA=/var/lib/postgresql/data \
    LANG=C.UTF-8
USER postgres
VOLUME /var/lib/postgresql/data
EXPOSE 5432
# Fast shutdown: SIGTERM would wait for every client to disconnect.
STOPSIGNAL SIGINT
HEALTHCHECK --interval=5s --timeout=3s --start-period=30s --retries=5 \
    CMD pg_isready -h 127.0.0.1 -p 5432 -q || exit 1
ENTRYPOINT ["postgres-entrypoint.sh"]
CMD ["postgres"]

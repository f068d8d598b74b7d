#!/usr/bin/env python3
"""The fault test of the multi-machine mode: one API process and four worker processes on
PostgreSQL (and the blob store given by AORTAGEN_BLOB_STORE), a 200-shape cohort at 32³,
and faults injected at random moments while it runs: `kill -9` of a worker (restarted
after a pause), and `SIGSTOP` of a worker past its lease, then `SIGCONT`, so that a stale
worker tries to commit late. Afterwards: exactly one shape per index, the job succeeded
with no live lease, every stored mesh present with the SHA-256 its row records, and every
mesh byte-identical to a single-process SQLite run of the same request.

Run by tests/fault/run.sh, which builds the binary and starts the servers:
    run.py BINARY MODELS_DIR POSTGRES_URL WORKDIR
"""

import hashlib
import json
import os
import random
import signal
import socket
import sqlite3
import subprocess
import sys
import time
import urllib.error
import urllib.request

COUNT = int(os.environ.get("FAULT_COUNT", "200"))
RESOLUTION = int(os.environ.get("FAULT_RESOLUTION", "32"))
WORKERS = 4
LEASE_SECS = 2
MIN_FAULTS = int(os.environ.get("FAULT_MIN_FAULTS", "10"))
MAX_FAULTS = MIN_FAULTS + 6
# Faults kept for the pairwise-metrics step (its tasks run once every shape is stored).
METRICS_FAULTS = 4
REQUEST = {"model_id": "default", "count": COUNT, "arity": 2, "weighting": "dirichlet",
           "seed": 20261205, "resolution": RESOLUTION}


def log(*args):
    print(time.strftime("%H:%M:%S"), *args, flush=True)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def http(method, url, body=None):
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(url, data=data, method=method,
                                 headers={"content-type": "application/json"})
    with urllib.request.urlopen(req, timeout=30) as r:
        return r.status, r.read()


def wait_healthy(base, proc, what):
    for _ in range(600):
        if proc.poll() is not None:
            sys.exit(f"{what} exited with {proc.returncode} before answering")
        try:
            if http("GET", base + "/healthz")[0] == 200:
                return
        except (urllib.error.URLError, ConnectionError, OSError):
            pass
        time.sleep(0.1)
    sys.exit(f"{what} never answered")


class Processes:
    def __init__(self, binary, workdir, env):
        self.binary, self.workdir, self.env = binary, workdir, env
        self.logs = []

    def start(self, name, *args, env=None):
        out = open(os.path.join(self.workdir, f"{name}.log"), "ab")
        self.logs.append(out.name)
        return subprocess.Popen([self.binary, *args], cwd=self.workdir,
                                env=dict(self.env, **(env or {})),
                                stdout=out, stderr=subprocess.STDOUT)


def start_worker(procs, i):
    # Each worker has a models directory of its own, empty at first: like a worker on
    # another machine it fetches the model from the object store by its digest.
    models = os.path.join(procs.workdir, f"worker-{i}-models")
    os.makedirs(models, exist_ok=True)
    return procs.start(f"worker-{i}", "worker", "--workers", "1",
                       env={"AORTAGEN_MODELS_DIR": models})


def cohort_status(base, cohort):
    return json.loads(http("GET", f"{base}/v1/cohorts/{cohort}")[1])


def psql(url, sql):
    out = subprocess.run(["psql", url, "-At", "-c", sql], check=True, capture_output=True,
                         text=True).stdout.strip()
    return out


def distributed_run(binary, models, pg_url, workdir):
    env = dict(os.environ, AORTAGEN_DATABASE_URL=pg_url, AORTAGEN_MODELS_DIR=models,
               AORTAGEN_LEASE_SECS=str(LEASE_SECS), AORTAGEN_LOG_JSON="true",
               RUST_LOG="aortagen=info")
    procs = Processes(binary, workdir, env)
    migrate = procs.start("migrate", "migrate")
    assert migrate.wait(timeout=120) == 0, "aortagen migrate failed"
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    api = procs.start("api", "serve", "--workers", "0", "--bind", f"127.0.0.1:{port}")
    wait_healthy(base, api, "the API")
    # The API has registered and published the model; its directory now leaves this
    # "machine", so the workers can only have the model from the object store.
    os.rename(models, models + ".api")
    workers = [start_worker(procs, i) for i in range(WORKERS)]
    status, body = http("POST", base + "/v1/cohorts", REQUEST)
    assert status == 202, body
    cohort = json.loads(body)["id"]
    log(f"cohort {cohort} posted: {COUNT} shapes at {RESOLUTION}³, {WORKERS} workers")
    rng = random.Random(7)
    faults = {"kill": 0, "stop": 0}
    started = time.time()
    while True:
        c = cohort_status(base, cohort)
        if c["status"] in ("succeeded", "failed", "cancelled"):
            break
        if time.time() - started > 1800:
            sys.exit("the cohort did not finish within 30 minutes")
        time.sleep(rng.uniform(0.3, 2.5))
        # Faults at a steady random rate until MAX_FAULTS, and METRICS_FAULTS more once the
        # shapes are stored and the metrics tasks run; then the run is left to finish.
        in_metrics = c["progress"]["done"] >= COUNT
        budget = MAX_FAULTS + (METRICS_FAULTS if in_metrics else 0)
        if faults["kill"] + faults["stop"] >= budget or rng.random() < 0.85:
            continue
        if in_metrics:
            faults["during metrics"] = faults.get("during metrics", 0) + 1
        victim = rng.randrange(WORKERS)
        if rng.random() < 0.5:
            workers[victim].kill()
            workers[victim].wait()
            faults["kill"] += 1
            log(f"kill -9 worker {victim} at {c['progress']['done']}/{COUNT}")
            time.sleep(rng.uniform(0.0, 1.0))
            workers[victim] = start_worker(procs, victim)
        else:
            workers[victim].send_signal(signal.SIGSTOP)
            faults["stop"] += 1
            pause = LEASE_SECS + rng.uniform(1.0, 3.0)
            log(f"SIGSTOP worker {victim} for {pause:.1f} s at {c['progress']['done']}/{COUNT}")
            time.sleep(pause)
            workers[victim].send_signal(signal.SIGCONT)
    elapsed = time.time() - started
    c = cohort_status(base, cohort)
    metrics = cohort_metrics(base, cohort) if c["status"] == "succeeded" else None
    log(f"cohort {c['status']} after {elapsed:.0f} s with {faults}")
    for w in workers:
        w.send_signal(signal.SIGTERM)
    for w in workers:
        w.wait(timeout=30)
    api.send_signal(signal.SIGTERM)
    api.wait(timeout=30)
    assert c["status"] == "succeeded", c
    assert faults["kill"] + faults["stop"] >= MIN_FAULTS, faults
    return cohort, faults, elapsed, procs.logs, metrics


def cohort_metrics(base, cohort):
    status, body = http("GET", f"{base}/v1/cohorts/{cohort}/metrics?matrix=true")
    assert status == 200, body
    m = json.loads(body)
    return {"summary": m["summary"], "matrix": m["matrix"]}


def reference_run(binary, models, workdir):
    db = os.path.join(workdir, "reference.db")
    env = dict(os.environ, AORTAGEN_DATABASE_URL=f"sqlite://{db}", AORTAGEN_MODELS_DIR=models)
    env.pop("AORTAGEN_BLOB_STORE", None)
    procs = Processes(binary, workdir, env)
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    api = procs.start("reference", "serve", "--workers", "2", "--bind", f"127.0.0.1:{port}")
    wait_healthy(base, api, "the reference service")
    status, body = http("POST", base + "/v1/cohorts", REQUEST)
    assert status == 202, body
    cohort = json.loads(body)["id"]
    while cohort_status(base, cohort)["status"] not in ("succeeded", "failed", "cancelled"):
        time.sleep(0.5)
    assert cohort_status(base, cohort)["status"] == "succeeded"
    metrics = cohort_metrics(base, cohort)
    api.send_signal(signal.SIGTERM)
    api.wait(timeout=30)
    with sqlite3.connect(db) as conn:
        return dict(conn.execute(
            "select shape_index, mesh_sha256 from shape where cohort_id = ?", (cohort,))), metrics


def stored_mesh(pg_url, sha):
    """The stored bytes of a mesh, from the blob store the service was given."""
    store = os.environ.get("AORTAGEN_BLOB_STORE", "db")
    if store == "db":
        hexed = psql(pg_url, f"select encode(bytes, 'hex') from blob where sha256 = '{sha}'")
        return bytes.fromhex(hexed) if hexed else None
    return fetch_object(store, sha)


def fetch_object(store, sha):
    # The store's own layout: {prefix}/sha256/{ab}/{hex}; read through the S3 API with
    # curl's SigV4 signing, or from the directory of a file store.
    key_tail = f"sha256/{sha[:2]}/{sha}"
    if store.startswith("file://"):
        path = os.path.join(store[len("file://"):], key_tail)
        return open(path, "rb").read() if os.path.exists(path) else None
    bucket_prefix = store[len("s3://"):]
    bucket, _, prefix = bucket_prefix.partition("/")
    key = f"{prefix}/{key_tail}" if prefix else key_tail
    endpoint = os.environ["AWS_ENDPOINT_URL"].rstrip("/")
    region = os.environ.get("AWS_REGION", "us-east-1")
    out = subprocess.run(
        ["curl", "-sf", "--aws-sigv4", f"aws:amz:{region}:s3", "--user",
         f"{os.environ['AWS_ACCESS_KEY_ID']}:{os.environ['AWS_SECRET_ACCESS_KEY']}",
         # S3 wants the payload hash header; curl signs it when it is given
         "-H", "x-amz-content-sha256: UNSIGNED-PAYLOAD",
         f"{endpoint}/{bucket}/{key}"], capture_output=True)
    return out.stdout if out.returncode == 0 else None


def main():
    binary, models, pg_url, workdir = sys.argv[1:5]
    cohort, faults, elapsed, logs, metrics = distributed_run(binary, models, pg_url, workdir)
    rows = psql(pg_url, f"select shape_index, mesh_sha256 from shape where cohort_id = {cohort} "
                        "order by shape_index").splitlines()
    shapes = {int(i): sha for i, sha in (r.split("|") for r in rows)}
    assert len(rows) == COUNT and sorted(shapes) == list(range(COUNT)), \
        f"{len(rows)} rows for {len(shapes)} indices"
    live = psql(pg_url, "select count(*) from task where status = 'running'")
    assert live == "0", f"{live} tasks still hold a lease"
    job = psql(pg_url, f"select status from job where job_id = "
                       f"(select job_id from cohort where cohort_id = {cohort})")
    assert job == "succeeded", job
    for index, sha in shapes.items():
        data = stored_mesh(pg_url, sha)
        assert data is not None, f"shape {index}: object {sha} is missing"
        assert hashlib.sha256(data).hexdigest() == sha, f"shape {index}: stored bytes differ"
    logs = sorted(set(logs))  # a restarted worker appends to its log file
    late = sum(open(p, errors="replace").read().count("lease was taken over") for p in logs)
    fetched = sum(open(p, errors="replace").read().count("model fetched from the object store")
                  for p in logs)
    assert fetched >= 1, "no worker fetched the model by its digest"
    log(f"{COUNT} shapes, one per index; every object present with its SHA-256; "
        f"{late} late commits or renewals refused")
    reference, reference_metrics = reference_run(binary, models + ".api", workdir)
    differing = [i for i in range(COUNT) if reference.get(i) != shapes[i]]
    assert not differing, f"meshes differ from the single-process run at {differing[:10]}"
    summary = metrics["summary"]
    assert metrics == reference_metrics, \
        "the pairwise metrics differ from the single-process run"
    log(f"every mesh byte-identical to the single-process SQLite run; the pairwise metrics "
        f"({summary['pairs']} of {summary['population_pairs']} pairs) identical too")
    print(json.dumps({"shapes": COUNT, "resolution": RESOLUTION, "workers": WORKERS,
                      "faults": faults, "seconds": round(elapsed, 1),
                      "late_refused": late, "model_fetches": fetched,
                      "pairs": summary["pairs"], "population_pairs": summary["population_pairs"]}))


if __name__ == "__main__":
    main()

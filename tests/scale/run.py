#!/usr/bin/env python3
"""Scale-out figures of the multi-machine mode on this machine: one API process
(`serve --workers 0`) and 1, then 2, `aortagen worker` processes on PostgreSQL and an
S3-compatible store, each run generating the same cohort. Reports shapes per minute and the
latency of metadata GETs (a cohort, a page of its shapes) issued continuously while the
workers run.

Run by tests/scale/run.sh, which builds the binary and starts the servers:
    run.py BINARY MODELS_DIR POSTGRES_SERVER_URL WORKDIR
SCALE_COUNT and SCALE_RESOLUTION override the cohort (40 shapes at 64³).
"""

import json
import os
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "fault"))
from run import Processes, cohort_status, free_port, http, log, wait_healthy  # noqa: E402

COUNT = int(os.environ.get("SCALE_COUNT", "40"))
RESOLUTION = int(os.environ.get("SCALE_RESOLUTION", "64"))


def poll_latencies(base, cohort, stop, out):
    paths = [f"/v1/cohorts/{cohort}", f"/v1/cohorts/{cohort}/shapes?limit=20"]
    n = 0
    while not stop.is_set():
        t = time.perf_counter()
        status, _ = http("GET", base + paths[n % 2])
        out.append(time.perf_counter() - t)
        assert status == 200
        n += 1
        time.sleep(0.02)


def one_run(binary, models, pg_url, workdir, workers):
    env = dict(os.environ, AORTAGEN_DATABASE_URL=pg_url, AORTAGEN_MODELS_DIR=models,
               AORTAGEN_LOG_JSON="true", RUST_LOG="aortagen=info")
    procs = Processes(binary, workdir, env)
    assert procs.start(f"migrate-{workers}", "migrate").wait(timeout=120) == 0
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    api = procs.start(f"api-{workers}", "serve", "--workers", "0", "--bind", f"127.0.0.1:{port}")
    wait_healthy(base, api, "the API")
    request = {"model_id": "default", "count": COUNT, "arity": 2, "weighting": "dirichlet",
               "seed": 20261206, "resolution": RESOLUTION}
    status, body = http("POST", base + "/v1/cohorts", request)
    assert status == 202, body
    cohort = json.loads(body)["id"]
    started = time.time()
    procs_w = [procs.start(f"worker-{workers}-{i}", "worker", "--workers", "1")
               for i in range(workers)]
    stop, latencies = threading.Event(), []
    poller = threading.Thread(target=poll_latencies, args=(base, cohort, stop, latencies))
    poller.start()
    while cohort_status(base, cohort)["status"] not in ("succeeded", "failed", "cancelled"):
        time.sleep(0.2)
    elapsed = time.time() - started
    stop.set()
    poller.join()
    final = cohort_status(base, cohort)
    for p in procs_w + [api]:
        p.terminate()
    for p in procs_w + [api]:
        p.wait(timeout=30)
    assert final["status"] == "succeeded", final
    latencies.sort()
    q = lambda p: latencies[round((len(latencies) - 1) * p)] * 1e3  # noqa: E731
    row = {"workers": workers, "shapes": COUNT, "resolution": RESOLUTION,
           "seconds": round(elapsed, 1), "shapes_per_min": round(COUNT / elapsed * 60, 1),
           "get_count": len(latencies), "get_p50_ms": round(q(0.5), 1),
           "get_p99_ms": round(q(0.99), 1)}
    log(json.dumps(row))
    return row


def main():
    binary, models, server, workdir = sys.argv[1:5]
    rows = []
    for workers in (1, 2):
        name = f"scale_{workers}"
        subprocess.run(["psql", server, "-q", "-c", f"create database {name}"], check=True)
        rows.append(one_run(binary, models, server.rsplit("/", 1)[0] + "/" + name, workdir,
                            workers))
    print(json.dumps(rows))


if __name__ == "__main__":
    main()

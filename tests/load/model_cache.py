#!/usr/bin/env python3
"""Memory of a service asked for cohorts at many resolutions.

Starts `BINARY serve` on a temporary database and a copy of the bundled model (one worker),
asks for a one-shape cohort at each of N resolutions in turn, and prints the server's
resident memory (VmRSS; VmHWM at the end) after each. Every new resolution makes the engine
build a novelty reference (the model's training surfaces sampled, with their search trees)
and keep it: an engine that keeps every reference it ever built grows with N, one whose
caches are bounded levels off.

    tests/load/model_cache.py BINARY [--first 32] [--resolutions 16]
"""

import argparse
import json
import pathlib
import shutil
import socket
import subprocess
import tempfile
import time
import urllib.request

ROOT = pathlib.Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def memory_kb(pid: int) -> dict:
    fields = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            key, _, value = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                fields[key] = int(value.split()[0])
    return fields


def request(base: str, method: str, path: str, body: bytes | None = None, headers=None):
    req = urllib.request.Request(base + path, data=body, method=method, headers=headers or {})
    with urllib.request.urlopen(req, timeout=120) as r:
        return json.loads(r.read() or b"null")


def wait_for(base: str, path: str, done, what: str, limit_s: float = 600.0):
    start = time.time()
    while time.time() - start < limit_s:
        view = request(base, "GET", path)
        if done(view):
            return view
        time.sleep(0.2)
    raise SystemExit(f"{what} not done within {limit_s} s: {view}")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("binary")
    parser.add_argument("--first", type=int, default=32)
    parser.add_argument("--resolutions", type=int, default=16)
    args = parser.parse_args()

    work = pathlib.Path(tempfile.mkdtemp(prefix="aortagen-cache-"))
    try:
        shutil.copytree(ROOT / "models/default", work / "models/default")
        port = free_port()
        log = open(work / "server.log", "w")
        server = subprocess.Popen(
            [args.binary, "serve", "--bind", f"127.0.0.1:{port}",
             "--database", f"sqlite://{work}/db.sqlite", "--models-dir", str(work / "models"),
             "--workers", "1"],
            stdout=log, stderr=subprocess.STDOUT)
        base = f"http://127.0.0.1:{port}"
        for _ in range(300):
            try:
                request(base, "GET", "/readyz")
                break
            except Exception:  # noqa: BLE001 - not listening yet
                time.sleep(0.1)
        print(f"started: {memory_kb(server.pid)}")
        print("| resolutions used | last | VmRSS (kB) | seconds |\n|---|---|---|---|")
        for k in range(args.resolutions):
            resolution = args.first + k
            start = time.time()
            cohort = request(base, "POST", "/v1/cohorts", json.dumps(
                {"model_id": "default", "count": 1, "arity": 2, "seed": k,
                 "resolution": resolution}).encode(), {"content-type": "application/json"})
            view = wait_for(base, f"/v1/cohorts/{cohort['id']}",
                            lambda v: v["status"] in ("succeeded", "failed"), f"cohort {k}")
            if view["status"] != "succeeded":
                raise SystemExit(f"cohort at {resolution} failed: {view}")
            rss = memory_kb(server.pid)["VmRSS"]
            print(f"| {k + 1} | {resolution} | {rss} | {time.time() - start:.1f} |", flush=True)
        print(f"end: {memory_kb(server.pid)}")
        server.terminate()
        server.wait(timeout=30)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()

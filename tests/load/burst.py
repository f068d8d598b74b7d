"""Burst of POST /v1/cohorts: every answer must be 202 or 429 (with Retry-After), the
server must stay up, and every accepted cohort must be listed afterwards."""

import http.client
import json
import sys
from collections import Counter
from concurrent.futures import ThreadPoolExecutor

HOST, PORT = sys.argv[1], int(sys.argv[2])
TOTAL = int(sys.argv[3]) if len(sys.argv) > 3 else 1000
THREADS = int(sys.argv[4]) if len(sys.argv) > 4 else 50


def post(i):
    body = json.dumps({"model_id": "default", "count": 1, "arity": 2,
                       "seed": 1_000_000 + i, "resolution": 32})
    conn = http.client.HTTPConnection(HOST, PORT, timeout=60)
    try:
        conn.request("POST", "/v1/cohorts", body, {"content-type": "application/json"})
        resp = conn.getresponse()
        data = resp.read()
        cohort = json.loads(data)["id"] if resp.status == 202 else None
        return resp.status, resp.getheader("Retry-After"), cohort
    except Exception as e:  # a refused or reset connection is a failure of the burst
        return f"error:{type(e).__name__}", None, None
    finally:
        conn.close()


def listed_ids():
    ids, offset = set(), 0
    while True:
        conn = http.client.HTTPConnection(HOST, PORT, timeout=60)
        conn.request("GET", f"/v1/cohorts?limit=100&offset={offset}")
        page = json.loads(conn.getresponse().read())
        conn.close()
        ids.update(c["id"] for c in page["items"])
        if page["next_offset"] is None:
            return ids
        offset = page["next_offset"]


before = listed_ids()
with ThreadPoolExecutor(THREADS) as pool:
    results = list(pool.map(post, range(TOTAL)))
statuses = Counter(r[0] for r in results)
accepted = {r[2] for r in results if r[0] == 202}
missing_retry_after = sum(1 for r in results if r[0] == 429 and not r[1])
after = listed_ids()
missing = accepted - after
unexpected = {s: n for s, n in statuses.items() if s not in (202, 429)}
print(f"BURST total={TOTAL} threads={THREADS} statuses={dict(statuses)} "
      f"accepted={len(accepted)} listed_new={len(after - before)} missing={len(missing)} "
      f"429_without_retry_after={missing_retry_after}")
ok = not unexpected and not missing and missing_retry_after == 0 \
    and len(after - before) == len(accepted)
sys.exit(0 if ok else 1)

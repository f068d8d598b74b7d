#!/usr/bin/env python3
"""Slow-header clients against a running aortagen service.

Opens N connections that each send an unfinished request header and then nothing, and
prints the server's open file descriptors and a /healthz round trip before, while the
clients hold their connections, and after a wait. A server with a header-read timeout
closes them; one without keeps every descriptor until the clients go away.

    tests/load/slowloris.py PID PORT [--clients 200] [--wait 30]
"""

import argparse
import os
import socket
import time
import urllib.request


def open_descriptors(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def health_ms(port: int) -> str:
    start = time.perf_counter()
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=10) as r:
            status = r.status
    except Exception as error:  # noqa: BLE001 - the figure reports any failure as it is
        return f"failed ({error})"
    return f"{status} in {(time.perf_counter() - start) * 1000:.1f} ms"


def closed_by_server(conn: socket.socket) -> bool:
    conn.setblocking(False)
    try:
        return conn.recv(1) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True
    finally:
        conn.setblocking(True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("pid", type=int)
    parser.add_argument("port", type=int)
    parser.add_argument("--clients", type=int, default=200)
    parser.add_argument("--wait", type=float, default=30.0)
    args = parser.parse_args()

    print(f"before: {open_descriptors(args.pid)} fds, healthz {health_ms(args.port)}")
    clients = []
    for _ in range(args.clients):
        conn = socket.create_connection(("127.0.0.1", args.port))
        conn.sendall(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\nX-Slow: ")
        clients.append(conn)
    time.sleep(1.0)
    print(
        f"{args.clients} slow clients: {open_descriptors(args.pid)} fds, "
        f"healthz {health_ms(args.port)}"
    )
    time.sleep(args.wait)
    closed = sum(closed_by_server(c) for c in clients)
    print(
        f"after {args.wait:.0f} s: {open_descriptors(args.pid)} fds, "
        f"{closed}/{args.clients} closed by the server, healthz {health_ms(args.port)}"
    )
    for conn in clients:
        conn.close()


if __name__ == "__main__":
    main()

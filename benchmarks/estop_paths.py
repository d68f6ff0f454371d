"""The e-stop's server paths without a browser: send -> arrival at each path.

Usage: python benchmarks/estop_paths.py [--presses 20]

`deltadash serve` on the simulator with its 3D scene; two telemetry WebSockets and two
status pollers (every 50 ms) load its event loop. Each press: two threads, released
together by a barrier, send ``POST /estop?press=ID`` to the e-stop listener and
``POST /api/estop?press=ID`` to the app, each on a fresh connection; then the press's
``estop_arrivals_unix_s`` (GET /api/status) gives when it reached the listener's thread,
the app's outermost middleware and the route's handler. Printed in ms, p50 / p90 /
worst, with the machine's load average (the figure is only as good as the CPU it got).
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import random
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
from websockets.sync.client import connect

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.support.server import Server, serve  # noqa: E402


def post(port: int, path: str) -> None:
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        connection.request("POST", path)
        connection.getresponse().read()
    finally:
        connection.close()


def send(barrier: threading.Barrier, sent: dict, key: str, port: int, path: str) -> None:
    """Wait for the other sender, note the time in ``sent[key]``, post."""
    barrier.wait()
    sent[key] = time.time()
    post(port, path)


def reset(server: Server, lease: str) -> None:
    request = urllib.request.Request(
        server.url + "/api/reset",
        data=b"{}",
        method="POST",
        headers={"Content-Type": "application/json", "X-Lease": lease},
    )
    with urllib.request.urlopen(request, timeout=10) as response:
        response.read()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presses", type=int, default=20)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder, serve(Path(folder), scene=True) as server:
        port = int(server.url.rsplit(":", 1)[1])
        listener = server.get("/api/info")["estop_port"]
        lease = server.post("/api/lease", {"client": "estop-paths"})["lease_id"]
        stop = threading.Event()

        def stream() -> None:
            with connect(f"ws://127.0.0.1:{port}/api/telemetry") as socket:
                while not stop.is_set():
                    json.loads(socket.recv())

        def poll() -> None:
            while not stop.is_set():
                server.get("/api/status")
                time.sleep(0.05)

        for target in (stream, stream, poll, poll):
            threading.Thread(target=target, daemon=True).start()
        time.sleep(2.0)
        print(f"load {os.getloadavg()}")
        found: dict[str, list[float]] = {"listener": [], "middleware": [], "route": []}
        for i in range(args.presses):
            if server.get("/api/status")["estopped"]:
                reset(server, lease)
            time.sleep(random.uniform(0.3, 0.8))
            press = f"p{i}-{os.getpid()}"
            barrier, sent = threading.Barrier(2), {}

            threads = [
                threading.Thread(
                    target=send, args=(barrier, sent, "listener", listener, f"/estop?press={press}")
                ),
                threading.Thread(
                    target=send, args=(barrier, sent, "app", port, f"/api/estop?press={press}")
                ),
            ]
            for thread in threads:
                thread.start()
            for thread in threads:
                thread.join()
            arrivals = server.get("/api/status")["estop_arrivals_unix_s"]
            found["listener"].append((arrivals["listener"] - sent["listener"]) * 1e3)
            for path in ("middleware", "route"):
                found[path].append((arrivals[path] - sent["app"]) * 1e3)
        stop.set()
        for path, values in found.items():
            a = np.asarray(values)
            print(
                f"send -> {path}: p50 {np.percentile(a, 50):.1f}  p90 {np.percentile(a, 90):.1f}"
                f"  worst {a.max():.1f} ms"
            )
        print(f"load after {os.getloadavg()}")


if __name__ == "__main__":
    main()

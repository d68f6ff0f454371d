"""What a flood of costly requests does to the control loop of a running server.

Issue 28: ``GET /api/workspace/nearest`` for far points cost 0.7-2.6 s of CPU per call in
the server's process; four clients pulled the loop from 159-164 Hz to 104-135 Hz, and a
refused goal (whose 422 offers the nearest accepted point) cost as much. Those queries now
run in worker processes (app/server/queries.py). This starts ``deltadash serve`` (the
emulated bus, no scene) as a process of its own and counts the loop's ticks over windows:
quiet, four clients flooding ``/api/status`` (cheap reads), four flooding
``/api/workspace/nearest`` with far points (a new point each time: no kept answer helps),
four flooding ``POST /api/goal`` with goals out of reach, and quiet again. It prints each
window's loop rate, its ratio to the mean of the quiet windows, and the requests answered
(503 = refused while the workers were busy).

Usage: python benchmarks/loop_read_flood.py [--window 10] [--clients 4]
"""

from __future__ import annotations

import argparse
import os
import platform
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import httpx
import numpy as np


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def ticks(client: httpx.Client) -> int:
    return client.get("/api/status").json()["loop"]["since_start"]["ticks"]


def flood(url: str, kind: str, stop: threading.Event, answers: Counter, seed: int) -> None:
    rng = np.random.default_rng(seed)
    with httpx.Client(base_url=url, timeout=30) as client:
        lease = {}
        if kind == "goal":
            taken = client.post("/api/lease", json={"client": f"flood{seed}", "take_over": True})
            lease = {"X-Lease": taken.json()["lease_id"]}
        while not stop.is_set():
            far = rng.uniform(-0.95, 0.95, 3)
            far[:2] += np.sign(far[:2]) * 0.4  # well outside the workspace
            far = np.clip(far, -0.99, 0.99)
            if kind == "status":
                response = client.get("/api/status")
            elif kind == "nearest":
                params = {"x_m": far[0], "y_m": far[1], "z_m": far[2]}
                response = client.get("/api/workspace/nearest", params=params)
            else:
                response = client.post(
                    "/api/goal", json={"position_m": far.tolist()}, headers=lease
                )
                if response.status_code == 409:  # another flooder took the lease
                    taken = client.post(
                        "/api/lease", json={"client": f"flood{seed}", "take_over": True}
                    )
                    lease = {"X-Lease": taken.json()["lease_id"]}
            answers[response.status_code] += 1


def window(url: str, kind: str | None, seconds: float, clients: int) -> tuple[float, Counter]:
    stop, answers = threading.Event(), Counter()
    threads = [
        threading.Thread(target=flood, args=(url, kind, stop, answers, k), daemon=True)
        for k in range(clients if kind else 0)
    ]
    with httpx.Client(base_url=url, timeout=30) as client:
        for thread in threads:
            thread.start()
        time.sleep(1.0)  # the flood under way
        before, start = ticks(client), time.monotonic()
        time.sleep(seconds)
        after, end = ticks(client), time.monotonic()
    stop.set()
    for thread in threads:
        thread.join(timeout=60)
    return (after - before) / (end - start), answers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--window", type=float, default=10.0, help="seconds per window")
    parser.add_argument("--clients", type=int, default=4, help="flooding clients")
    args = parser.parse_args()
    port = free_port()
    with tempfile.TemporaryDirectory() as folder:
        config = Path(folder) / "config.toml"
        config.write_text(
            f'[server]\nscene = false\nhttp_port = {port}\n[runs]\nfolder = "{folder}"\n'
        )
        command = [sys.executable, "-m", "app.cli", "serve", "--config", str(config)]
        command += ["--backend", "emulated"]
        server = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        url = f"http://127.0.0.1:{port}"
        try:
            deadline = time.monotonic() + 60
            while True:
                try:
                    if httpx.get(f"{url}/api/status", timeout=2).status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                if time.monotonic() > deadline or server.poll() is not None:
                    raise SystemExit("the server did not start")
                time.sleep(0.2)
            print(
                f"{platform.node()} {os.cpu_count()} CPUs, Python {platform.python_version()}, "
                f"{args.clients} clients, {args.window:g} s windows"
            )
            rates: dict[str, float] = {}
            for name, kind in (
                ("quiet", None),
                ("status flood", "status"),
                ("nearest flood (far)", "nearest"),
                ("refused-goal flood", "goal"),
                ("quiet again", None),
            ):
                rate, answers = window(url, kind, args.window, args.clients)
                rates[name] = rate
                quiet = np.mean([rates[k] for k in ("quiet", "quiet again") if k in rates])
                shown = ", ".join(f"{code}: {n}" for code, n in sorted(answers.items()))
                print(
                    f"{name:<22} {rate:6.1f} Hz  {rate / quiet:5.2f}x quiet  "
                    f"load {os.getloadavg()[0]:4.1f}  answers {shown or '-'}"
                )
            quiet = (rates["quiet"] + rates["quiet again"]) / 2
            worst = min(rates[k] for k in rates if "flood" in k)
            print(f"worst flood / quiet: {worst / quiet:.3f}x (goal: at least 0.95x)")
        finally:
            server.terminate()
            server.wait(timeout=30)


if __name__ == "__main__":
    main()

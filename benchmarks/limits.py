"""Time to refuse a large body, and to plan the largest run the API accepts.

Usage: python benchmarks/limits.py [--backend sim|emulated] [--mb 16] [--repeats 5]

Starts `deltadash serve --token ...` as a subprocess and measures, over raw sockets:
- POST /api/goal with a --mb MB JSON body and no token: time from the request's headers
  to the 401's status line (the server must answer without reading the body);
- the same with the token: time to the 413 (over server.max_body_bytes);
- POST /api/tests/waypoints with 1,000 points over 600 s (torque on, the arm settled):
  time to the answer, and whether the loop's worst tick over those seconds grew.
The loop's worst tick is read from /api/status (last 10 s) when idle and after each group;
the machine's load average is printed, as on a shared machine it sets the figures.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import socket
import statistics
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request

PORT = 8767
VISER_PORT = 8768
TOKEN = "benchmark-token-123"
LEASE: dict[str, str] = {}  # X-Lease once taken: commands need the control lease


def _http(method: str, path: str, body: dict | None = None, timeout: float = 60) -> dict:
    request = urllib.request.Request(
        f"http://127.0.0.1:{PORT}{path}",
        data=None if body is None else json.dumps(body).encode(),
        method=method,
        headers={
            "content-type": "application/json",
            "authorization": f"Bearer {TOKEN}",
            **LEASE,
        },
    )
    with urllib.request.urlopen(request, timeout=timeout) as response:
        return json.load(response)


def _wait_up(timeout_s: float = 60.0) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        try:
            _http("GET", "/api/status")
            return
        except OSError:
            time.sleep(0.2)
    raise RuntimeError("server did not come up")


def time_to_status(size: int, token: str | None) -> tuple[float, int]:
    """Seconds from the headers sent to the status line received, and the status code.
    The body is streamed from another thread meanwhile (the server may never read it)."""
    with socket.create_connection(("127.0.0.1", PORT)) as sock:
        headers = (
            f"POST /api/goal HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
            f"Content-Length: {size}\r\n"
            + (f"Authorization: Bearer {token}\r\n" if token else "")
            + "\r\n"
        )
        body = b'{"position_m": [0, 0, -0.24], "pad": "' + b"x" * (size - 40) + b'"}'
        body = body[:size].ljust(size, b" ")
        began = time.perf_counter()
        sock.sendall(headers.encode())

        def stream() -> None:
            with contextlib.suppress(OSError):  # the server answered and closed
                sock.sendall(body)

        sender = threading.Thread(target=stream, daemon=True)
        sender.start()
        line = sock.makefile("rb").readline()
        took = time.perf_counter() - began
    return took, int(line.split()[1])


def worst_tick_ms() -> float:
    return _http("GET", "/api/status")["loop"]["last_10s"]["worst_ms"]


def waypoints_body() -> dict:
    count, radius = 1000, 0.03
    points = [[radius * math.cos(i / 10), radius * math.sin(i / 10), -0.24] for i in range(count)]
    points[0] = [0.0, 0.0, -0.24]
    return {"points_m": points, "times_s": [600.0 * i / (count - 1) for i in range(count)]}


def settle() -> None:
    if not LEASE:
        lease = _http("POST", "/api/lease", {"client": "benchmarks/limits.py", "take_over": True})
        LEASE["x-lease"] = lease["lease_id"]
    _http("POST", "/api/torque", {"enabled": True})
    _http("POST", "/api/goal", {"position_m": [0.0, 0.0, -0.24]})
    end = time.monotonic() + 30
    while time.monotonic() < end:
        status = _http("GET", "/api/status")
        still = max(abs(v or 0) for v in status["joints"]["velocity_rad_s"]) < 0.02
        if still and math.dist(status["ee"]["commanded_m"], [0, 0, -0.24]) < 1e-6:
            return
        time.sleep(0.2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backend", default="sim", choices=["sim", "emulated"])
    parser.add_argument("--mb", type=float, default=16.0)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    env = {
        **os.environ,
        "DELTADASH_HARDWARE__BACKEND": args.backend,
        "DELTADASH_SERVER__HTTP_PORT": str(PORT),
        "DELTADASH_SERVER__VISER_PORT": str(VISER_PORT),
        "DELTADASH_SERVER__TOKEN": TOKEN,
    }
    server = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    size = int(args.mb * (1 << 20))
    try:
        _wait_up()
        time.sleep(11)  # the startup out of the loop's last-10-s window
        print(
            f"idle: loop worst tick (last 10 s) {worst_tick_ms():.2f} ms; "
            f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
        )
        for label, token in (("no token -> 401", None), ("token -> 413", TOKEN)):
            results = [time_to_status(size, token) for _ in range(args.repeats)]
            times_ms = [1e3 * t for t, _ in results]
            print(
                f"{args.mb:g} MB body, {label}: statuses {sorted({s for _, s in results})}, "
                f"time to the status line median {statistics.median(times_ms):.1f} ms, "
                f"max {max(times_ms):.1f} ms ({args.repeats} tries); "
                f"loop worst tick (last 10 s) {worst_tick_ms():.2f} ms"
            )
        settle()
        began = time.perf_counter()
        try:
            answer = _http("POST", "/api/tests/waypoints", waypoints_body(), timeout=300)
            outcome = f"started run {answer['run_id']}"
        except urllib.error.HTTPError as exc:
            outcome = f"{exc.code}: {json.load(exc)['detail'][:100]}"
        took = time.perf_counter() - began
        print(
            f"1,000 waypoints over 600 s: answered in {took:.2f} s ({outcome}); "
            f"loop worst tick (last 10 s) {worst_tick_ms():.2f} ms"
        )
    finally:
        server.terminate()
        server.wait(timeout=20)


if __name__ == "__main__":
    main()

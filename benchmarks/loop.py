"""Control-loop timing under load: `deltadash serve` with WebSocket telemetry clients.

Usage: python benchmarks/loop.py [--backend emulated] [--seconds 60] [--clients 5]
                                 [--rates 200,500,1000] [--torque]
                                 [--viser-clients 3] [--browsers 3]

Starts the server as a subprocess per loop rate, connects telemetry clients at 50 Hz
(and with --torque enables torque and jogs the robot in a circle), and after the run
prints the loop's own figures from /api/status (rate, lateness p50/p99, worst tick,
overruns) and the server's CPU use. Lateness is how far a tick started after its deadline.
Beside the server, benchmarks/clock_floor.py ticks a bare clock over the same seconds: the
machine's floor (kernel wake-up, a VM's vCPU descheduled), printed under each result.
--viser-clients opens raw WebSocket clients on the 3D scene (the server's whole cost of a
viewer, no rendering); --browsers opens the scene in headless chromium pages (Debian's
chromium via Playwright, software WebGL: on a 2-core machine they compete for the CPU).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import platform
import subprocess
import sys
import time
import urllib.request

import websockets

PORT = 8765
VISER_PORT = 8766
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]


_LEASE: dict[str, str] = {}  # X-Lease once taken: commands need the control lease


def _http(method: str, path: str, body: dict | None = None) -> dict:
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(
        f"http://127.0.0.1:{PORT}{path}",
        data=data,
        method=method,
        headers={"content-type": "application/json", **_LEASE},
    )
    with urllib.request.urlopen(request, timeout=5) as response:
        return json.load(response)


def _wait_up(timeout_s: float = 30.0) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        try:
            _http("GET", "/api/status")
            return
        except OSError:
            time.sleep(0.2)
    raise RuntimeError("server did not come up")


async def _client(seconds: float) -> int:
    count = 0
    async with websockets.connect(f"ws://127.0.0.1:{PORT}/api/telemetry?hz=50") as ws:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            await ws.recv()
            count += 1
    return count


def _camera_message() -> bytes:
    """What a browser sends first: viser counts a client as connected from its camera."""
    import msgspec
    from viser import _messages

    camera = _messages.ViewerCameraMessage(
        (1.0, 0.0, 0.0, 0.0),
        (0.5, -0.6, 0.1),
        1.3,
        0.01,
        100.0,
        800,
        1280,
        (0.0, 0.0, -0.2),
        (0.0, 0.0, 1.0),
    )
    return msgspec.msgpack.encode(camera.as_serializable_dict())


async def _viser_client(seconds: float) -> int:
    import viser

    count, protocol = 0, websockets.Subprotocol(f"viser-v{viser.__version__}")
    async with websockets.connect(
        f"ws://127.0.0.1:{VISER_PORT}", subprotocols=[protocol], max_size=None
    ) as ws:
        await ws.send(_camera_message())
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            try:
                await asyncio.wait_for(ws.recv(), timeout=left)
            except TimeoutError:
                break
            count += 1
    return count


async def _browsers(count: int, seconds: float) -> None:
    from playwright.async_api import async_playwright

    async with async_playwright() as playwright:
        browsers = [
            await playwright.chromium.launch(
                executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS
            )
            for _ in range(count)
        ]
        for browser in browsers:
            page = await browser.new_page(viewport={"width": 1280, "height": 800})
            await page.goto(f"http://127.0.0.1:{VISER_PORT}/")
        await asyncio.sleep(seconds)
        for browser in browsers:
            await browser.close()


async def _jog_circle(seconds: float) -> None:
    end, t = time.monotonic() + seconds, 0.0
    while time.monotonic() < end:
        goal = [0.04 * math.cos(t), 0.04 * math.sin(t), -0.23]
        await asyncio.to_thread(_http, "POST", "/api/goal", {"position_m": goal})
        t += 0.2
        await asyncio.sleep(0.1)


def _stat(pid: int) -> list[str]:
    with open(f"/proc/{pid}/stat") as file:
        return file.read().rsplit(")", 1)[1].split()


def _cpu_s(pid: int) -> float:
    fields = _stat(pid)
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _children_cpu_s(pid: int) -> float:
    """CPU of the server's live child processes (the simulator, the servo emulator)."""
    total = 0.0
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                if int(_stat(int(entry))[1]) == pid:
                    total += _cpu_s(int(entry))
            except (OSError, IndexError, ValueError):
                continue  # gone meanwhile
    return total


async def _load(args: argparse.Namespace) -> list[int]:
    tasks = [_client(args.seconds) for _ in range(args.clients)]
    tasks += [_viser_client(args.seconds) for _ in range(args.viser_clients)]
    if args.browsers:
        tasks.append(_browsers(args.browsers, args.seconds))
    if args.torque:
        tasks.append(_jog_circle(args.seconds))
    return await asyncio.gather(*tasks)


def run_once(args: argparse.Namespace, rate_hz: float) -> None:
    env = {
        **os.environ,
        "DELTADASH_HARDWARE__BACKEND": args.backend,
        "DELTADASH_LOOP__RATE_HZ": str(rate_hz),
        "DELTADASH_SERVER__HTTP_PORT": str(PORT),
        "DELTADASH_SERVER__VISER_PORT": str(VISER_PORT),
    }
    server = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        _wait_up()
        lease = _http("POST", "/api/lease", {"client": "benchmarks/loop.py", "take_over": True})
        _LEASE["x-lease"] = lease["lease_id"]
        if args.torque:
            _http("POST", "/api/torque", {"enabled": True})
        floor = None if args.no_floor else _start_floor(args.seconds, rate_hz)
        cpu0, children0, wall0 = _cpu_s(server.pid), _children_cpu_s(server.pid), time.monotonic()
        received = asyncio.run(_load(args))
        wall = time.monotonic() - wall0
        cpu = (_cpu_s(server.pid) - cpu0) / wall
        children = (_children_cpu_s(server.pid) - children0) / wall
        loop = _http("GET", "/api/status")["loop"]["since_start"]
        floor_line = floor.communicate(timeout=60)[0].strip() if floor else ""
    finally:
        server.terminate()
        server.wait(timeout=10)
    telemetry = [r for r in received[: args.clients] if r is not None]
    scene = [r for r in received[args.clients : args.clients + args.viser_clients]]
    messages = min(telemetry) if telemetry else 0
    print(
        f"{args.backend:9} {rate_hz:6.0f} Hz target: measured {loop['measured_hz']:7.1f} Hz, "
        f"lateness p50 {loop['jitter_p50_ms']:.2f} ms p99 {loop['jitter_p99_ms']:.2f} ms, "
        f"worst {loop['worst_ms']:.2f} ms, overruns {loop['overruns']}/{loop['ticks']}, "
        f"server CPU {100 * cpu:.0f} % of a core (+{100 * children:.0f} % in its child "
        f"processes), telemetry msgs/client {messages}"
        + (f", scene clients {args.viser_clients} (msgs/client {min(scene)})" if scene else "")
        + (f", browsers on the scene {args.browsers}" if args.browsers else "")
    )
    if floor_line:
        print(floor_line + " (same seconds, beside the server)")


def _start_floor(seconds: float, rate_hz: float) -> subprocess.Popen:
    """The machine's floor over the same seconds: a bare clock in its own process."""
    script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "clock_floor.py")
    return subprocess.Popen(
        [sys.executable, script, "--seconds", str(seconds), "--rate", str(rate_hz)],
        stdout=subprocess.PIPE,
        text=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--backend", default="emulated", choices=["sim", "emulated"])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--clients", type=int, default=5)
    parser.add_argument("--rates", default="200")
    parser.add_argument("--torque", action="store_true", help="enable torque and jog meanwhile")
    parser.add_argument("--viser-clients", type=int, default=0, help="WebSocket scene viewers")
    parser.add_argument("--browsers", type=int, default=0, help="headless chromium scene pages")
    parser.add_argument("--no-floor", action="store_true", help="skip the bare-clock floor")
    args = parser.parse_args()
    print(
        f"python {platform.python_version()}, {os.cpu_count()} cores, {platform.machine()}, "
        f"load average {os.getloadavg()[0]:.2f}"
    )
    for rate in args.rates.split(","):
        run_once(args, float(rate))


if __name__ == "__main__":
    main()

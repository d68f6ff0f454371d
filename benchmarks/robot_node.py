"""The robot node (issue 30): the loop isolated from its station, the link's round trip,
and a lost station's motion to standstill.

Usage:
  python benchmarks/robot_node.py isolation [--window 10] [--rate 200]
  python benchmarks/robot_node.py link [--count 500] [--netns]
  python benchmarks/robot_node.py lost [--repeat 5]

``isolation``: ``deltadash serve`` on the twin, once with the loop in a robot node of its
own (``link.robot = embedded``, the default) and once in the station's process
(``in-process``, the architecture before), each over two windows: the station idle, then
saturated (25 telemetry WebSocket clients, 4 clients flooding ``GET /api/status``, 2
flooding G-code checks and 2 flooding far nearest-point queries at once). Beside each
window a bare clock (benchmarks/clock_floor.py) runs in a process of its own: the
machine's floor at that moment. The loop's figures are its own (``/api/status``
``loop.last_10s``: lateness p99, overruns over the ticks of the window).

``link``: a robot node (``deltadash robot``) and a station (a RobotClient over Zenoh) in
two processes; the round trip of a command that needs no tick (``info``) and of one the
loop runs (``torque``, answered once a snapshot shows it), p50 / p99, and the rate at
which the station receives states. On loopback; with ``--netns`` (root) also between two
network namespaces joined by a veth pair, through a TCP proxy in the benchmark that delays
each chunk by 5 +- 5 ms and 1 % of them by another 200 ms (Linux's minimum
retransmission timeout: what a lost segment costs TCP; this kernel has no netem).

``lost``: a robot node, a station (``deltadash serve --robot``) jogging the arm with
hold-to-move at 20 and 100 mm/s, and a passive Zenoh listener on the node's state and on
the station's heartbeats; the station is killed (SIGKILL) mid-jog, and the time from its
last heartbeat to the arm at rest (the commanded point still, then the measured one within
0.2 mm of it) is printed per try.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import os
import platform
import random
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

# this folder holds a kinematics.py that would shadow the package
sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != os.path.dirname(__file__)]
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import httpx  # noqa: E402
import numpy as np  # noqa: E402

CIRCLE = (ROOT / "examples" / "circle.ngc").read_text()
WIFI_STATION_TIMEOUT_S = 0.5  # the node's link.station_timeout_s between the namespaces


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def machine() -> str:
    return f"{platform.node()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"


@contextlib.contextmanager
def served(
    folder: Path, robot: str, rate_hz: float, extra_env: dict | None = None
) -> Iterator[tuple[str, subprocess.Popen]]:
    """``deltadash serve`` (the twin, no scene) with ``link.robot = robot``: its URL and
    its process."""
    port = free_port()
    env = {
        **os.environ,
        "DELTADASH_SERVER__HTTP_PORT": str(port),
        "DELTADASH_SERVER__SCENE": "false",
        "DELTADASH_RUNS__FOLDER": str(folder / "runs"),
        "DELTADASH_LINK__ROBOT": robot,
        "DELTADASH_LOOP__RATE_HZ": str(rate_hz),
        **(extra_env or {}),
    }
    process = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=(folder / "serve.log").open("wb"),
    )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                if httpx.get(f"{url}/api/status", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline or process.poll() is not None:
                raise SystemExit(f"the server did not start: {(folder / 'serve.log').read_text()}")
            time.sleep(0.2)
        yield url, process
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()


# ---- isolation -------------------------------------------------------------------------
def _telemetry_clients(url: str, count: int, stop: threading.Event) -> threading.Thread:
    import websockets

    async def one() -> None:
        async with websockets.connect(url.replace("http", "ws") + "/api/telemetry") as ws:
            while not stop.is_set():
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(ws.recv(), 0.5)

    async def every() -> None:
        await asyncio.gather(*(one() for _ in range(count)), return_exceptions=True)

    thread = threading.Thread(target=lambda: asyncio.run(every()), daemon=True)
    thread.start()
    return thread


def _flood(url: str, kind: str, stop: threading.Event, seed: int) -> None:
    rng = np.random.default_rng(seed)
    with httpx.Client(base_url=url, timeout=60) as client:
        while not stop.is_set():
            try:
                if kind == "status":
                    client.get("/api/status")
                elif kind == "check":
                    client.post("/api/programs/check", json={"gcode": CIRCLE})
                else:
                    far = np.clip(rng.uniform(-0.95, 0.95, 3) * 1.5, -0.99, 0.99)
                    params = {"x_m": far[0], "y_m": far[1], "z_m": far[2]}
                    client.get("/api/workspace/nearest", params=params)
            except httpx.HTTPError:
                pass


def _loop_window(url: str, seconds: float) -> dict:
    """The loop's own figures over a window: ticks, overruns, lateness p99 (its last 10 s)."""
    with httpx.Client(base_url=url, timeout=30) as client:
        before = client.get("/api/status").json()["loop"]["since_start"]
        time.sleep(seconds)
        status = client.get("/api/status").json()["loop"]
    after = status["since_start"]
    ticks = after["ticks"] - before["ticks"]
    return {
        "ticks": ticks,
        "overruns": after["overruns"] - before["overruns"],
        "p99_ms": status["last_10s"]["jitter_p99_ms"],
        "rate_hz": ticks / seconds,
    }


def _floor(seconds: float, rate_hz: float) -> subprocess.Popen:
    return subprocess.Popen(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "clock_floor.py"),
            "--seconds",
            str(seconds),
            "--rate",
            str(rate_hz),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )


def _window(url: str, seconds: float, rate_hz: float, saturate: bool) -> tuple[dict, str]:
    stop = threading.Event()
    threads: list[threading.Thread] = []
    if saturate:
        threads.append(_telemetry_clients(url, 25, stop))
        for k, kind in enumerate(["status"] * 4 + ["check"] * 2 + ["nearest"] * 2):
            thread = threading.Thread(target=_flood, args=(url, kind, stop, k), daemon=True)
            thread.start()
            threads.append(thread)
        time.sleep(2.0)  # the flood under way
    floor = _floor(seconds, rate_hz)
    figures = _loop_window(url, seconds)
    floor_line = floor.communicate(timeout=seconds + 30)[0].strip()
    stop.set()
    for thread in threads:
        thread.join(timeout=60)
    return figures, floor_line


def isolation(args: argparse.Namespace) -> None:
    print(f"{machine()}; {args.window:g} s windows at {args.rate:g} Hz")
    for robot in ("embedded", "in-process"):
        with (
            tempfile.TemporaryDirectory() as folder,
            served(Path(folder), robot, args.rate) as (url, _),
        ):
            time.sleep(3.0)  # settled after the start
            for name, saturate in (("idle", False), ("saturated", True)):
                figures, floor = _window(url, args.window, args.rate, saturate)
                share = 100.0 * figures["overruns"] / max(1, figures["ticks"])
                print(
                    f"{robot:<11} {name:<9} loop {figures['rate_hz']:6.1f} Hz, lateness p99 "
                    f"{figures['p99_ms']:.3f} ms, overruns {figures['overruns']}/"
                    f"{figures['ticks']} ({share:.2f} %), load {os.getloadavg()[0]:.1f} | {floor}"
                )


# ---- link ------------------------------------------------------------------------------
@contextlib.contextmanager
def node_process(endpoint: str, folder: Path, netns: str | None = None) -> Iterator[None]:
    env = {**os.environ, "DELTADASH_RUNS__FOLDER": str(folder / "runs")}
    command = [sys.executable, "-m", "app.cli", "robot", "--backend", "sim", "--listen", endpoint]
    if netns:
        command = ["ip", "netns", "exec", netns, *command]
        env["DELTADASH_LINK__USER"], env["DELTADASH_LINK__PASSWORD"] = "bench", "bench-password"
        # a lossy link (a TCP segment lost costs 200 ms) would lose 60 ms heartbeats
        env["DELTADASH_LINK__STATION_TIMEOUT_S"] = str(WIFI_STATION_TIMEOUT_S)
    log = folder / "robot.log"
    process = subprocess.Popen(command, env=env, stdout=log.open("wb"), stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120
        while "listening on" not in log.read_text(errors="replace"):
            if process.poll() is not None or time.monotonic() > deadline:
                raise SystemExit(f"the robot node did not start: {log.read_text()}")
            time.sleep(0.1)
        yield
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()


def _round_trips(endpoint: str, count: int, login: bool) -> dict:
    from app.config import load_settings
    from app.link.client import RobotClient
    from app.link.zenoh_station import StationTransport

    link = {"robot": endpoint}
    if login:
        link |= {"user": "bench", "password": "bench-password"}
    settings = load_settings(link=link, server={"command_timeout_s": 10.0})
    transport = StationTransport(settings.link, endpoint)
    client = RobotClient(settings, transport)
    deadline = time.monotonic() + 60
    while True:
        try:
            client.start()
            break
        except Exception:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
    try:
        out: dict = {}
        for op, args in (("info", {}), ("torque", {"enabled": False})):
            times = []
            for _ in range(count):
                start = time.perf_counter()
                client.request(op, args).result(timeout=10)
                times.append(time.perf_counter() - start)
            times.sort()
            out[op] = (1e3 * times[len(times) // 2], 1e3 * times[int(0.99 * len(times)) - 1])
        before, start = transport.state_received, time.monotonic()
        time.sleep(5.0)
        out["state_hz"] = (transport.state_received - before) / (time.monotonic() - start)
        return out
    finally:
        client.stop()


class DelayProxy:
    """TCP proxy: each chunk delayed 5 +- 5 ms, 1 % another 200 ms, order kept."""

    def __init__(self, listen: tuple[str, int], target: tuple[str, int], seed: int = 1) -> None:
        self.listen, self.target, self.rng = listen, target, random.Random(seed)
        self.server = socket.create_server(listen, reuse_port=False)
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            client, _ = self.server.accept()
            upstream = socket.create_connection(self.target)
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=self._pipe, args=(a, b), daemon=True).start()

    def _pipe(self, source: socket.socket, sink: socket.socket) -> None:
        import queue

        chunks: queue.Queue = queue.Queue()

        def send() -> None:
            while True:
                due, data = chunks.get()
                if data is None:
                    return
                time.sleep(max(0.0, due - time.monotonic()))
                sink.sendall(data)

        threading.Thread(target=send, daemon=True).start()
        last_due = 0.0
        while True:
            data = source.recv(65536)
            if not data:
                chunks.put((0.0, None))
                return
            delay = self.rng.uniform(0.0, 0.010)
            if self.rng.random() < 0.01:
                delay += 0.200
            last_due = max(last_due, time.monotonic() + delay)
            chunks.put((last_due, data))


def _netns_up() -> None:
    script = """
ip netns del dd-robot 2>/dev/null; ip netns del dd-station 2>/dev/null
ip netns add dd-robot; ip netns add dd-station
ip link add dd-veth-r type veth peer name dd-veth-s
ip link set dd-veth-r netns dd-robot; ip link set dd-veth-s netns dd-station
ip -n dd-robot addr add 10.77.0.1/24 dev dd-veth-r; ip -n dd-robot link set dd-veth-r up
ip -n dd-station addr add 10.77.0.2/24 dev dd-veth-s; ip -n dd-station link set dd-veth-s up
ip -n dd-robot link set lo up; ip -n dd-station link set lo up
"""
    subprocess.run(["sh", "-c", script], check=True)


def _netns_down() -> None:
    subprocess.run(["sh", "-c", "ip netns del dd-robot; ip netns del dd-station"], check=False)


def link(args: argparse.Namespace) -> None:
    print(f"{machine()}; {args.count} commands of each kind")
    with tempfile.TemporaryDirectory() as folder:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        with node_process(endpoint, Path(folder)):
            shown = _round_trips(endpoint, args.count, login=False)
        print(_link_line("loopback", shown))
    if not args.netns:
        return
    _netns_up()
    try:
        with (
            tempfile.TemporaryDirectory() as folder,
            node_process("tcp/10.77.0.1:7447", Path(folder), netns="dd-robot"),
        ):
            print(f"(between the namespaces: link.station_timeout_s {WIFI_STATION_TIMEOUT_S} s)")
            for name, proxy in (("veth, two netns", False), ("veth + 5+-5 ms, 1 % +200 ms", True)):
                # the station in the other namespace: a process of its own (setns(2) moves
                # one thread, and Zenoh's runtime threads would stay behind)
                command = ["ip", "netns", "exec", "dd-station", sys.executable, __file__]
                command += ["station", "--count", str(args.count)] + (["--proxy"] if proxy else [])
                out = subprocess.run(command, capture_output=True, text=True, timeout=600)
                if out.returncode != 0:
                    raise SystemExit(out.stderr)
                print(_link_line(name, json.loads(out.stdout.strip().splitlines()[-1])))
    finally:
        _netns_down()


def station(args: argparse.Namespace) -> None:
    """(in the station's namespace) the round trips to the node in the robot's, directly
    or through the delaying proxy; one JSON line."""
    endpoint = "tcp/10.77.0.1:7447"
    if args.proxy:
        DelayProxy(("10.77.0.2", 7448), ("10.77.0.1", 7447))
        endpoint = "tcp/10.77.0.2:7448"
    print(json.dumps(_round_trips(endpoint, args.count, login=True)), flush=True)
    os._exit(0)  # the proxy's threads: nothing to wait for


def _link_line(name: str, shown: dict) -> str:
    info, torque = shown["info"], shown["torque"]
    return (
        f"{name:<28} info p50 {info[0]:6.2f} ms p99 {info[1]:6.2f} ms | torque (a tick) "
        f"p50 {torque[0]:6.2f} ms p99 {torque[1]:6.2f} ms | states {shown['state_hz']:6.1f}/s"
    )


# ---- lost station ----------------------------------------------------------------------
def lost(args: argparse.Namespace) -> None:
    import zenoh

    from app.config import LinkSettings
    from app.control.state import Snapshot
    from app.link.codec import decode
    from app.link.protocol import Keys
    from app.link.zenoh_session import zenoh_config

    print(f"{machine()}; link.station_timeout_s 0.06, held jog renewed every 50 ms")
    with tempfile.TemporaryDirectory() as folder:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        with node_process(endpoint, Path(folder)):
            config, cleanup = zenoh_config(LinkSettings(), connect=endpoint)
            session = zenoh.open(config)
            keys = Keys()
            states: list[tuple[float, Snapshot]] = []
            beats: list[float] = []
            session.declare_subscriber(
                keys.state,
                lambda s: states.append((time.monotonic(), decode(Snapshot, s.payload.to_bytes()))),
            )
            session.declare_subscriber(keys.heartbeats, lambda s: beats.append(time.monotonic()))
            for speed in (0.02, 0.1):
                tries = [
                    _one_loss(Path(folder), endpoint, speed, states, beats)
                    for _ in range(args.repeat)
                ]
                for name, values in (
                    ("the node's stop (braking from there)", [s for s, _, _ in tries]),
                    ("command still", [c for _, c, _ in tries]),
                    ("arm at rest (0.2 mm)", [r for _, _, r in tries]),
                ):
                    shown = ", ".join(f"{v * 1e3:.0f}" for v in values)
                    print(
                        f"{speed * 1e3:5.0f} mm/s: last heartbeat to {name}: {shown} ms "
                        f"(median {statistics.median(values) * 1e3:.0f} ms)"
                    )
            session.close()
            cleanup()


def _one_loss(folder: Path, endpoint: str, speed: float, states: list, beats: list) -> float:
    env = {"DELTADASH_LINK__STATION_TIMEOUT_S": "0.06"}
    with (
        served(folder, endpoint, 200.0, env) as (url, station),
        httpx.Client(base_url=url, timeout=10) as c,
    ):
        lease = c.post("/api/lease", json={"client": "bench", "take_over": True}).json()
        headers = {"X-Lease": lease["lease_id"]}
        deadline = time.monotonic() + 30
        while c.post("/api/torque", json={"enabled": True}, headers=headers).status_code != 200:
            if time.monotonic() > deadline:
                raise SystemExit("torque on refused for 30 s")
            time.sleep(0.3)
        c.post("/api/move", json={"position_m": [-0.05, 0.0, -0.24]}, headers=headers)
        time.sleep(2.0)
        end = time.monotonic() + 0.6  # a held jog along +x, renewed like a pressed key
        while time.monotonic() < end:
            c.post("/api/jog", json={"velocity_m_s": [speed, 0.0, 0.0]}, headers=headers)
            time.sleep(0.05)
        station.kill()
        killed = time.monotonic()
        time.sleep(1.5)
    last_beat = max(b for b in beats if b <= killed + 0.01)
    after = [(t, snap) for t, snap in states if t >= last_beat]
    said = next((t for t, snap in after if "link was lost" in (snap.notice or "")), math.nan)
    commanded = rest = math.nan
    for k in range(1, len(after)):
        t, snap = after[k]
        moved = np.linalg.norm(snap.point_commanded_m - after[k - 1][1].point_commanded_m)
        if moved < 1e-6 and math.isnan(commanded):
            commanded = t - last_beat  # the node's command stands still
        settled = np.linalg.norm(snap.point_measured_m - snap.point_commanded_m) < 2e-4
        if not math.isnan(commanded) and settled:
            rest = t - last_beat  # and the arm has caught up with it
            break
    return said - last_beat, commanded, rest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    iso = commands.add_parser("isolation")
    iso.add_argument("--window", type=float, default=10.0)
    iso.add_argument("--rate", type=float, default=200.0)
    iso.set_defaults(run=isolation)
    lnk = commands.add_parser("link")
    lnk.add_argument("--count", type=int, default=500)
    lnk.add_argument("--netns", action="store_true", help="also between two network namespaces")
    lnk.set_defaults(run=link)
    sta = commands.add_parser("station", help=argparse.SUPPRESS)
    sta.add_argument("--count", type=int, default=500)
    sta.add_argument("--proxy", action="store_true")
    sta.set_defaults(run=station)
    lst = commands.add_parser("lost")
    lst.add_argument("--repeat", type=int, default=5)
    lst.set_defaults(run=lost)
    args = parser.parse_args()
    args.run(args)


if __name__ == "__main__":
    main()

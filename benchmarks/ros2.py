"""The robot node's ROS 2 topics (issue 31): JointState's rate and latency at a subscriber
in another process, and the loop with the ROS publishing on against off.

Usage: python benchmarks/ros2.py [--window 20] [--rounds 2] [--rate 200]

A robot node (``deltadash robot`` on the twin) runs alone, ``[ros2] publish`` off and on
in turn (``--rounds`` times each, interleaved); this process is a passive Zenoh peer on
the node's state key (the loop's own figures: lateness p99 and overruns over the window,
from its ``loop_total`` and ``loop_window``) and, while the publishing is on, on every ROS
topic of its domain (so the samples are really sent). For each JointState it takes the
time of arrival (``time.time()``) less the message's stamp (the wall time of the tick it
came from, taken in the node right after the tick): the latency from the robot node's
tick to a subscriber, both clocks the same machine's. Beside each window a bare clock
(benchmarks/clock_floor.py) runs in a process of its own: the machine's floor then.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

# this folder holds a kinematics.py that would shadow the package
sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != os.path.dirname(__file__)]
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import zenoh  # noqa: E402

from app.config import LinkSettings  # noqa: E402
from app.control.state import Snapshot  # noqa: E402
from app.link.codec import decode  # noqa: E402
from app.link.zenoh_session import zenoh_config  # noqa: E402
from app.ros2.messages import JOINT_STATE, typestore  # noqa: E402

DOMAIN = 42


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@contextlib.contextmanager
def node(folder: Path, publish: bool, rate_hz: float) -> Iterator[str]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = {
        **os.environ,
        "DELTADASH_RUNS__FOLDER": str(folder / "runs"),
        "DELTADASH_ROS2__PUBLISH": str(publish).lower(),
        "DELTADASH_ROS2__DOMAIN_ID": str(DOMAIN),
        "DELTADASH_LOOP__RATE_HZ": str(rate_hz),
    }
    log = folder / "robot.log"
    command = [sys.executable, "-m", "app.cli", "robot", "--backend", "sim", "--listen", endpoint]
    process = subprocess.Popen(command, env=env, stdout=log.open("wb"), stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120
        while "listening on" not in log.read_text(errors="replace"):
            if process.poll() is not None or time.monotonic() > deadline:
                raise SystemExit(f"the robot node did not start: {log.read_text()}")
            time.sleep(0.1)
        yield endpoint
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()


def floor(seconds: float, rate_hz: float) -> subprocess.Popen:
    script = ROOT / "benchmarks" / "clock_floor.py"
    command = [sys.executable, str(script), "--seconds", str(seconds), "--rate", str(rate_hz)]
    return subprocess.Popen(command, stdout=subprocess.PIPE, text=True)


def window(endpoint: str, seconds: float, rate_hz: float, publish: bool) -> str:
    store = typestore("jazzy")
    states: list[Snapshot] = []
    arrivals: list[tuple[float, float]] = []  # (arrival, stamp) [s since the epoch]
    other = [0]

    def on_state(sample: zenoh.Sample) -> None:
        states.append(decode(Snapshot, sample.payload.to_bytes()))

    def on_ros(sample: zenoh.Sample) -> None:
        now = time.time()
        if "JointState" not in str(sample.key_expr):
            other[0] += 1
            return
        message = store.deserialize_cdr(sample.payload.to_bytes(), JOINT_STATE)
        stamp = message.header.stamp.sec + message.header.stamp.nanosec * 1e-9
        arrivals.append((now, stamp))

    config, cleanup = zenoh_config(LinkSettings(), connect=endpoint)
    session = zenoh.open(config)
    try:
        session.declare_subscriber("deltadash/robot/state", on_state)
        if publish:
            session.declare_subscriber(f"{DOMAIN}/**", on_ros)
        deadline = time.monotonic() + 60
        while not states and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(2.0)  # settled
        bare = floor(seconds, rate_hz)
        first, n0 = states[-1], len(arrivals)
        time.sleep(seconds)
        last = states[-1]
        floor_line = bare.communicate(timeout=seconds + 30)[0].strip()
    finally:
        session.close()
        cleanup()
    ticks = last.loop_total.ticks - first.loop_total.ticks
    overruns = last.loop_total.overruns - first.loop_total.overruns
    line = (
        f"publish {'on ' if publish else 'off'}: loop {ticks / seconds:6.1f} Hz, lateness p99 "
        f"{last.loop_window.jitter_p99_ms:.3f} ms, overruns {overruns}/{ticks}"
    )
    if publish:
        window_arrivals = arrivals[n0:]
        latency = sorted((a - s) * 1e3 for a, s in window_arrivals)
        p50 = statistics.median(latency)
        p99 = latency[min(len(latency) - 1, int(0.99 * len(latency)))]
        line += (
            f"; JointState {len(window_arrivals) / seconds:.1f} /s, tick to subscriber "
            f"p50 {p50:.2f} ms, p99 {p99:.2f} ms, max {latency[-1]:.2f} ms "
            f"(+{other[0]} other ROS samples)"
        )
    return f"{line} | {floor_line}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--window", type=float, default=20.0)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--rate", type=float, default=200.0)
    args = parser.parse_args()
    print(
        f"{platform.node()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; "
        f"{args.window:g} s windows, loop at {args.rate:g} Hz, ROS at its default rate"
    )
    for _ in range(args.rounds):
        for publish in (False, True):
            with (
                tempfile.TemporaryDirectory() as folder,
                node(Path(folder), publish, args.rate) as endpoint,
            ):
                print(window(endpoint, args.window, args.rate, publish), flush=True)


if __name__ == "__main__":
    main()

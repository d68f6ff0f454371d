"""Round-trip time of one control tick through dynamixel-sdk, a pty and the emulator.

Usage: python benchmarks/bus.py [--ticks 10000] [--emulator process|thread] [--servos 3|4]

One tick = DynamixelBus.write_goal (one Sync Write of Goal Position to 3 servos, or 4 with
a wrist) plus DynamixelBus.read_state (one Sync Read of the 25-byte state block, one status
packet per servo), the
exact per-tick path of the control loop, units converted. By default the emulator runs in
its own process (``python -m hardware.emulator``) like a separate device on the wire;
``--emulator thread`` runs it in this process, where it competes for the GIL with the SDK's
polling reads. Return Delay Time is 0 (the factory 500 us would add 1.5 ms per tick).
Prints p50/p99/max per tick, the loop rate p99 allows, and the wire-time arithmetic for
real servos.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

# This folder holds files named like modules (bus.py): keep it off the import path.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

from hardware.calibration import JointCalibration  # noqa: E402
from hardware.dynamixel.control_table import STATE_BLOCK_SIZE, Reg  # noqa: E402
from hardware.dynamixel.driver import DynamixelBus, DynamixelConfig  # noqa: E402
from hardware.emulator import ServoEmulator  # noqa: E402

IDS = (1, 2, 3)  # the legs; --servos 4 adds a wrist (id 4)


@contextmanager
def emulated_port(where: str, ids: tuple[int, ...] = IDS):
    """The pty path of emulated servos `ids` (Return Delay Time 0), in a process or a thread."""
    if where == "thread":
        with ServoEmulator(ids) as emulator:
            for servo in emulator.servos:
                servo.table.set(Reg.RETURN_DELAY_TIME, 0)
            yield emulator.port
        return
    command = [sys.executable, "-m", "hardware.emulator", "--ids", ",".join(map(str, ids))]
    process = subprocess.Popen(
        [*command, "--return-delay-us", "0"], stdout=subprocess.PIPE, text=True
    )
    try:
        yield process.stdout.readline().strip()
    finally:
        process.terminate()
        process.wait(timeout=10)


def measure(port: str, ticks: int, warmup: int = 500, ids: tuple[int, ...] = IDS) -> np.ndarray:
    """Seconds per tick (sync write + sync read), `ticks` samples after `warmup`."""
    joints = tuple(JointCalibration(i) for i in ids)
    bus = DynamixelBus(DynamixelConfig(joints=joints, port=port, baudrate=1_000_000))
    bus.connect()
    try:
        bus.torque(True)
        samples = np.empty(ticks)
        for k in range(-warmup, ticks):
            goal = 0.3 * math.sin(2 * math.pi * k / 400)  # a 2 s sine at 200 Hz
            start = time.perf_counter()
            bus.write_goal([goal, -goal, 0.5 * goal, 2 * goal][: len(ids)])
            bus.read_state()
            if k >= 0:
                samples[k] = time.perf_counter() - start
        failures = bus.stats.failures
        bus.torque(False)
    finally:
        bus.disconnect()
    if failures:
        print(f"warning: {failures} failed transactions during the run")
    return samples


def cpu_model() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return platform.processor() or "unknown CPU"
    for line in out.splitlines():
        if line.startswith("Model name:"):
            return line.split(":", 1)[1].strip()
    return "unknown CPU"


def wire_arithmetic(n: int = len(IDS)) -> None:
    """Bytes on a real bus per tick with `n` servos and their time at 1 and 4 Mbps (10 bits
    per byte)."""
    sync_write = 14 + n * (1 + 4)  # header..CRC with (id + 4 data bytes) per servo
    sync_read = 14 + n  # header..CRC with one id per servo
    status = 11 + STATE_BLOCK_SIZE  # one status packet per servo
    total = sync_write + sync_read + n * status
    print(
        f"\nreal bus per tick: sync write {sync_write} B + sync read {sync_read} B + "
        f"{n} x status {status} B = {total} B"
    )
    for mbps in (1, 4):
        wire_ms = total * 10 / (mbps * 1e3)
        print(
            f"  {mbps} Mbps: wire {wire_ms:.2f} ms; + USB latency timer 1 ms"
            f" -> ~{wire_ms + 1:.2f} ms; with the FTDI default 16 ms -> ~{wire_ms + 16:.1f} ms"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=10_000)
    parser.add_argument("--emulator", choices=("process", "thread"), default="process")
    parser.add_argument(
        "--servos", type=int, choices=(3, 4), default=3, help="3 legs, or 4 with a wrist"
    )
    args = parser.parse_args(argv)
    ids = (*IDS, 4) if args.servos == 4 else IDS
    print(f"machine: {cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    # Other processes on a 2-core machine show up in the tail: say how busy it was.
    print("load average at start: " + ", ".join(f"{x:.2f}" for x in os.getloadavg()))
    with emulated_port(args.emulator, ids) as port:
        samples = measure(port, args.ticks, ids=ids)
    p50, p90, p99 = np.percentile(samples, [50, 90, 99]) * 1e6
    over = int(np.sum(samples > 1e-3))
    print(
        f"tick (sync write + sync read, {len(ids)} servos, emulator in a {args.emulator}), "
        f"{args.ticks} ticks:"
    )
    print(
        f"  p50 {p50:.0f} us   p90 {p90:.0f} us   p99 {p99:.0f} us   "
        f"max {samples.max() * 1e6:.0f} us   mean {samples.mean() * 1e6:.0f} us"
    )
    print(f"  ticks over 1 ms: {over} of {len(samples)}")
    print(f"  max loop rate at p99: {1e6 / p99:.0f} Hz (target p99 <= 1000 us)")
    wire_arithmetic(len(ids))
    return 0


if __name__ == "__main__":
    sys.exit(main())

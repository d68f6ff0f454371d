"""The machine's floor for a control loop: the loop's clock with no work and no other threads.

Usage: python benchmarks/clock_floor.py [--seconds 30] [--rate 200] [--spin 0.0003]

Runs the control loop's TickClock and TimingRecorder (app/control/timing.py) in a bare
process and prints the same figures the server reports: whatever lateness this shows
(the kernel's wake-up latency, the hypervisor descheduling the VM's vCPU) no loop on this
machine can beat. benchmarks/loop.py runs it beside the server, over the same seconds,
so each server figure comes with the machine's floor at that moment.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

# this folder holds a kinematics.py that would shadow the package
sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != os.path.dirname(__file__)]
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from app.control.timing import TickClock, TimingRecorder, TimingStats  # noqa: E402


def measure(seconds: float, rate_hz: float, spin_s: float) -> TimingStats:
    """Tick for `seconds` with no work; the lateness of every tick, as the server counts it."""
    clock, recorder = TickClock(rate_hz, spin_s), TimingRecorder(rate_hz)
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        deadline, lateness = clock.wait_next()
        recorder.record(deadline, lateness, 0.0)
    return recorder.since_start()


def describe(stats: TimingStats) -> str:
    return (
        f"lateness p50 {stats.jitter_p50_ms:.2f} ms p99 {stats.jitter_p99_ms:.2f} ms, "
        f"worst {stats.worst_ms:.2f} ms, overruns {stats.overruns}/{stats.ticks}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--rate", type=float, default=200.0)
    parser.add_argument("--spin", type=float, default=3e-4, help="busy-wait before a deadline [s]")
    args = parser.parse_args()
    stats = measure(args.seconds, args.rate, args.spin)
    print(f"floor     {args.rate:6.0f} Hz bare clock: {describe(stats)}")


if __name__ == "__main__":
    main()

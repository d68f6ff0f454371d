"""Hold-to-move's dead man's switch: time from a held jog's last heartbeat to standstill.

Usage: python benchmarks/jog_deadman.py [--trials 10] [--speeds 0.02 0.05 0.2]

An app on the MuJoCo twin (in-process, over HTTP with FastAPI's TestClient, as the page
talks to it). Each trial: torque on at (0, 0, -240) mm, hold a jog along +x at one speed
with a heartbeat (POST /api/jog {"velocity_m_s": ...}) every 50 ms for 0.5 s, then stop
sending, as a killed client would. A listener in the control thread records every tick's
commanded point and notice; the stop is the first tick after which the point never
changes again. Printed per speed, from the last heartbeat (the loop time it was taken,
from its reply): the time to the loop's decision to brake (the "no heartbeat" notice) and
to standstill [ms], median and worst, and the distance travelled after the heartbeat [mm];
and the machine's load, since the figure is only as good as the CPU it got.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fastapi.testclient import TestClient  # noqa: E402

from app.config import load_settings  # noqa: E402
from app.server import create_app  # noqa: E402

START_M = [0.0, 0.0, -0.24]
HEARTBEAT_S = 0.05


def ok(response) -> dict:
    assert response.status_code == 200, response.text
    return response.json()


def until(condition, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError("the robot did not get there")
        time.sleep(0.01)


def trial(client: TestClient, controller, speed_m_s: float) -> tuple[float, float, float, bool]:
    """From the last heartbeat: ms to the loop's decision to stop (the notice appears), ms
    to standstill, mm travelled; and whether the hold was cut short before (a heartbeat
    came later than the timeout: on a loaded machine the deadman works both ways)."""
    ok(client.post("/api/reset"))  # a loaded machine can starve the twin into a fault
    ok(client.post("/api/torque", json={"enabled": True}))
    ok(client.post("/api/goal", json={"position_m": START_M}))
    commanded = lambda: controller.snapshot().point_commanded_m  # noqa: E731
    until(lambda: np.allclose(commanded(), START_M, atol=1e-6))
    ticks: list[tuple[float, np.ndarray, str]] = []

    def listener(snap) -> None:
        ticks.append((snap.time_s, snap.point_commanded_m.copy(), snap.notice or ""))

    controller.add_listener(listener)
    try:
        last = {}
        for _ in range(round(0.5 / HEARTBEAT_S)):
            body = {"velocity_m_s": [speed_m_s, 0.0, 0.0]}
            last = ok(client.post("/api/jog", json=body))["result"]
            time.sleep(HEARTBEAT_S)
        beat_s = last["time_s"]
        until(lambda: ticks[-1][0] > beat_s + 1.0)  # long after any stop
    finally:
        controller.remove_listener(listener)
    times = np.array([t for t, _, _ in ticks])
    points = np.array([p for _, p, _ in ticks])
    decided = next(t for t, _, notice in ticks if t >= beat_s and "no heartbeat" in notice)
    cut = any(t < beat_s and "no heartbeat" in notice for t, _, notice in ticks)
    moving = np.flatnonzero(np.linalg.norm(np.diff(points, axis=0), axis=1) > 1e-9)
    stop = moving[-1] + 1  # the first tick with the final point
    at_beat = points[np.searchsorted(times, beat_s)]
    travelled = float(np.linalg.norm(points[stop] - at_beat))
    return 1e3 * (decided - beat_s), 1e3 * (times[stop] - beat_s), 1e3 * travelled, cut


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--speeds", type=float, nargs="+", default=[0.02, 0.05, 0.2])
    args = parser.parse_args()
    settings = load_settings(
        runs={"folder": tempfile.mkdtemp(prefix="deltadash-runs-")}, server={"viser_port": 0}
    )
    print(
        f"hold timeout {settings.jog.hold_timeout_s} s, loop {settings.loop.rate_hz:g} Hz, "
        f"heartbeat every {HEARTBEAT_S * 1e3:.0f} ms; load {os.getloadavg()[0]:.2f}"
    )
    with TestClient(create_app(settings)) as client:
        lease = ok(client.post("/api/lease", json={"client": "jog_deadman", "take_over": True}))
        client.headers["X-Lease"] = lease["lease_id"]
        controller = client.app.state.controller
        for speed in args.speeds:
            results = [trial(client, controller, speed) for _ in range(args.trials)]
            decided, stops, after, cut = ([r[i] for r in results] for i in range(4))
            print(
                f"{speed * 1e3:4.0f} mm/s: braking from {statistics.median(decided):4.0f} ms "
                f"(worst {max(decided):4.0f}), standstill at {statistics.median(stops):4.0f} ms "
                f"(worst {max(stops):4.0f}) after the last heartbeat; "
                f"{statistics.median(after):.1f} mm (worst {max(after):.1f}) travelled "
                f"after it; {args.trials} trials, {sum(cut)} cut short by a late "
                "heartbeat"
            )
    print(f"load after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()

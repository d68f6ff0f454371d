"""Calibration on the twin built wrong: RMSE before and after, offsets found, time taken.

Usage: python benchmarks/calibration_twin.py [--poses 40 120] [--parameters offsets geometry]
       [--rods] [--apply] [--measurement external pose-input]

An app on the MuJoCo twin (in-process, over HTTP with FastAPI's TestClient) built with
joint offsets of (3, -2, 2.5) deg, 0.3 mm of motion-capture noise per axis and a
measurement frame moved (0.1, -0.05, -0.5) m and turned (0.02, -0.01, 1.5) rad from the
base; --rods also makes the rods 244.0, 242.5, 243.0 mm (nominal 243.0) and the upper
links 155.8, 156.3, 155.5 mm (nominal 155.8). Each case: POST /api/calibration/run, wait
for it, print the condition number, the offsets' errors [deg], the RMSE (3D distance of
FK from the measurement, the arm at rest, 20 ticks averaged) before (nominal model, its
frame fitted) and after on the fit and held-out poses [mm], and the run's wall time.

--apply (gravity compensation on: the P loop alone sags ~1 mm under any model) also sends
goals to three points before the run and again after applying it, and prints how far from
each the platform came to rest by the twin's own measurement (30 samples averaged, mapped
to the base frame with the twin's true measurement frame) [mm].

--measurement pose-input measures by motion capture through the pose input instead: a
stand-in (tests/support/mocap.py) streams the twin's view of its platform at 100 Hz over
UDP as body "platform", its world frame shifted (0.2, -0.1, 0.05) m from the twin's own.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fastapi.testclient import TestClient  # noqa: E402

from app.config import load_settings  # noqa: E402
from app.server import create_app  # noqa: E402

OFFSETS_DEG = (3.0, -2.0, 2.5)
TWIN = {
    "true_joint_offsets_rad": [math.radians(d) for d in OFFSETS_DEG],
    "measurement_frame_position_m": [0.1, -0.05, -0.5],
    "measurement_frame_rpy_rad": [0.02, -0.01, 1.5],
    "measurement_noise_m": 3e-4,
}
RODS = {
    "true_lower_link_m": [0.2440, 0.2425, 0.2430],
    "true_upper_link_m": [0.1558, 0.1563, 0.1555],
}
GOALS_M = ([0.03, 0.0, -0.25], [-0.04, 0.05, -0.22], [0.0, -0.06, -0.28])
LANDING_SAMPLES = 30


def landing_misses_m(client) -> list[float]:
    """For each of GOALS_M: send it, wait until the arm holds it still, and return how far
    the twin's measurement (averaged, base frame) is from it [m]."""
    from kinematics.identification import MeasurementFrame

    frame = MeasurementFrame(
        tuple(TWIN["measurement_frame_position_m"]), tuple(TWIN["measurement_frame_rpy_rad"])
    )
    misses = []
    for goal in GOALS_M:
        ok(client.post("/api/goal", json={"position_m": goal}))
        deadline = time.monotonic() + 60
        while True:
            status = ok(client.get("/api/status"))
            held = np.linalg.norm(np.subtract(status["ee"]["commanded_m"], goal)) < 1e-4
            still = all(abs(v or 0.0) < 0.02 for v in status["joints"]["velocity_rad_s"])
            if held and still:
                break
            if time.monotonic() > deadline:
                raise TimeoutError(f"the arm did not come to rest at {goal}")
            time.sleep(0.05)
        seen, last = [], -1
        while len(seen) < LANDING_SAMPLES:
            status = ok(client.get("/api/status"))
            if status["loop"]["ticks"] != last:
                last = status["loop"]["ticks"]
                seen.append(frame.to_base(status["ee"]["external_m"]))
        misses.append(float(np.linalg.norm(np.mean(seen, axis=0) - goal)))
    return misses


def ok(response) -> dict:
    assert response.status_code == 200, response.text
    return response.json()


def case(
    poses: int, parameters: str, rods: bool, apply: bool = False, measurement: str = "external"
) -> None:
    from tests.support.mocap import TwinMocap, free_udp_port

    sim = {**TWIN, **(RODS if rods else {})}
    landed = ""
    port = free_udp_port()
    with tempfile.TemporaryDirectory() as folder:
        settings = load_settings(
            hardware={"backend": "sim", "sim": sim},
            server={"scene": False},
            runs={"folder": folder},
            safety={"stale_feedback_s": 5.0, "following_error_time_s": 5.0},
            control={"gravity_compensation": apply},
            world={"udp_port": port},
        )
        with TestClient(create_app(settings)) as client:
            lease = ok(client.post("/api/lease", json={"client": "bench", "take_over": True}))
            client.headers["X-Lease"] = lease["lease_id"]
            deadline = time.monotonic() + 60
            while client.post("/api/torque", json={"enabled": True}).status_code != 200:
                if time.monotonic() > deadline:
                    raise TimeoutError("torque on refused for a minute")
                time.sleep(0.2)  # the relaxed arm comes to rest inside its limits
            before = landing_misses_m(client) if apply else []
            mocap = TwinMocap(client.app.state.backend.bus, port, shift_m=(0.2, -0.1, 0.05))
            with contextlib.ExitStack() as stack:
                if measurement == "pose-input":
                    stack.enter_context(mocap.streaming())
                    while ok(client.get("/api/mav/pose?body=platform"))["state"] != "ok":
                        time.sleep(0.05)
                began = time.monotonic()
                body = {"poses": poses, "parameters": parameters, "measurement": measurement}
                run_id = ok(client.post("/api/calibration/run", json=body))["run_id"]
                while (run := ok(client.get(f"/api/calibration/{run_id}")))["state"] in (
                    "planned",
                    "moving",
                    "fitting",
                ):
                    time.sleep(0.5)
                took = time.monotonic() - began
            if apply and run["state"] == "done":
                ok(client.post(f"/api/calibration/{run_id}/apply"))
                after = landing_misses_m(client)
                shown = lambda m: ", ".join(f"{v * 1e3:.2f}" for v in m)  # noqa: E731
                landed = f" {shown(before)} -> {shown(after)} |"
            if args_keep := os.environ.get("CALIBRATION_KEEP"):
                import shutil

                shutil.copytree(Path(folder) / "calibration", args_keep, dirs_exist_ok=True)
    if run["parameters"] is None:
        print(f"{poses} poses, {parameters}: {run['state']}: {run['error']}")
        return
    error = np.degrees(run["parameters"]["joint_offsets_rad"]) - OFFSETS_DEG
    mm = lambda key: f"{run[key] * 1e3:.2f}"  # noqa: E731
    print(
        f"| {parameters} | {measurement} | {poses} ({run['holdout_poses']} held out) "
        f"| {'yes' if rods else 'no'} "
        f"| {run['condition_number']:.1f} | {np.abs(error).max():.3f} "
        f"| {mm('rmse_before_m')} -> {mm('rmse_after_m')} "
        f"| {mm('holdout_rmse_before_m')} -> {mm('holdout_rmse_m')} | {run['state']} "
        f"| {took:.0f} s |{landed}",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--poses", type=int, nargs="+", default=[40])
    parser.add_argument("--parameters", nargs="+", default=["offsets", "geometry"])
    parser.add_argument("--rods", action="store_true", help="rods and links off by up to 1 mm")
    parser.add_argument(
        "--apply", action="store_true", help="apply the fit; goals' landing before and after"
    )
    parser.add_argument(
        "--measurement",
        nargs="+",
        default=["external"],
        choices=("external", "pose-input"),
        help="the twin's own measurement, or motion capture streamed to the pose input",
    )
    args = parser.parse_args()
    print(f"load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    landing = " goals' miss before -> after apply [mm] |" if args.apply else ""
    print(
        "| fitted | measurement | poses | rods off | condition number | worst offset error [deg] "
        f"| RMSE fit poses [mm] | RMSE held out [mm] | state | time |{landing}"
    )
    print("| --- " * (11 if args.apply else 10) + "|")
    for measurement in args.measurement:
        for parameters in args.parameters:
            for poses in args.poses:
                case(poses, parameters, args.rods, args.apply, measurement)


if __name__ == "__main__":
    main()

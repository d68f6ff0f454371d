"""Calibration on the twin built wrong: RMSE before and after, offsets found, time taken.

Usage: python benchmarks/calibration_twin.py [--poses 40 120] [--parameters offsets geometry]
       [--rods]

An app on the MuJoCo twin (in-process, over HTTP with FastAPI's TestClient) built with
joint offsets of (3, -2, 2.5) deg, 0.3 mm of motion-capture noise per axis and a
measurement frame moved (0.1, -0.05, -0.5) m and turned (0.02, -0.01, 1.5) rad from the
base; --rods also makes the rods 244.0, 242.5, 243.0 mm (nominal 243.0) and the upper
links 155.8, 156.3, 155.5 mm (nominal 155.8). Each case: POST /api/calibration/run, wait
for it, print the condition number, the offsets' errors [deg], the RMSE (3D distance of
FK from the measurement, the arm at rest, 20 ticks averaged) before (nominal model, its
frame fitted) and after on the fit and held-out poses [mm], and the run's wall time.
"""

from __future__ import annotations

import argparse
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


def ok(response) -> dict:
    assert response.status_code == 200, response.text
    return response.json()


def case(poses: int, parameters: str, rods: bool) -> None:
    sim = {**TWIN, **(RODS if rods else {})}
    with tempfile.TemporaryDirectory() as folder:
        settings = load_settings(
            hardware={"backend": "sim", "sim": sim},
            server={"scene": False},
            runs={"folder": folder},
            safety={"stale_feedback_s": 5.0, "following_error_time_s": 5.0},
        )
        with TestClient(create_app(settings)) as client:
            lease = ok(client.post("/api/lease", json={"client": "bench", "take_over": True}))
            client.headers["X-Lease"] = lease["lease_id"]
            deadline = time.monotonic() + 60
            while client.post("/api/torque", json={"enabled": True}).status_code != 200:
                if time.monotonic() > deadline:
                    raise TimeoutError("torque on refused for a minute")
                time.sleep(0.2)  # the relaxed arm comes to rest inside its limits
            began = time.monotonic()
            body = {"poses": poses, "parameters": parameters}
            run_id = ok(client.post("/api/calibration/run", json=body))["run_id"]
            while (run := ok(client.get(f"/api/calibration/{run_id}")))["state"] in (
                "planned",
                "moving",
                "fitting",
            ):
                time.sleep(0.5)
            took = time.monotonic() - began
            if args_keep := os.environ.get("CALIBRATION_KEEP"):
                import shutil

                shutil.copytree(Path(folder) / "calibration", args_keep, dirs_exist_ok=True)
    if run["parameters"] is None:
        print(f"{poses} poses, {parameters}: {run['state']}: {run['error']}")
        return
    error = np.degrees(run["parameters"]["joint_offsets_rad"]) - OFFSETS_DEG
    mm = lambda key: f"{run[key] * 1e3:.2f}"  # noqa: E731
    print(
        f"| {parameters} | {poses} ({run['holdout_poses']} held out) | {'yes' if rods else 'no'} "
        f"| {run['condition_number']:.1f} | {np.abs(error).max():.3f} "
        f"| {mm('rmse_before_m')} -> {mm('rmse_after_m')} "
        f"| {mm('holdout_rmse_before_m')} -> {mm('holdout_rmse_m')} | {run['state']} "
        f"| {took:.0f} s |",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--poses", type=int, nargs="+", default=[40])
    parser.add_argument("--parameters", nargs="+", default=["offsets", "geometry"])
    parser.add_argument("--rods", action="store_true", help="rods and links off by up to 1 mm")
    args = parser.parse_args()
    print(f"load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(
        "| fitted | poses | rods off | condition number | worst offset error [deg] "
        "| RMSE fit poses [mm] | RMSE held out [mm] | state | time |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for parameters in args.parameters:
        for poses in args.poses:
            case(poses, parameters, args.rods)


if __name__ == "__main__":
    main()

"""A geometry calibration applied end to end on the twin built wrong on purpose (issue 20).

The twin's joints are offset by a few degrees, its rods, upper links and base radii are
off by up to a millimetre, and its motion capture sits in a frame of its own with 0.3 mm
of noise. The controller starts with the nominal (drawn) robot, so a goal lands millimetres
from where it was sent, by the twin's own measurement. After a geometry calibration and
its apply, the controller's model is the fitted per-leg robot and a goal lands within
0.5 mm of where it was sent; the config file holds that robot, and reads back as it.

Gravity compensation is on: the servos' P loop alone lets the arm sag about 1 mm below any
goal under its own weight, whatever the model (docs/server.md, gravity compensation).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from app.config import load_settings
from kinematics import PerLegRotaryDelta
from kinematics.identification import MeasurementFrame
from tests.support.app_client import make_client, settle_at, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

TWIN = {
    "true_joint_offsets_rad": [math.radians(d) for d in (3.0, -2.0, 2.5)],
    "true_upper_link_m": [0.1562, 0.1558, 0.1553],
    "true_lower_link_m": [0.2440, 0.2423, 0.2430],
    "true_base_radius_m": [0.0844, 0.0851, 0.0838],
    "measurement_frame_position_m": [0.1, -0.05, -0.5],
    "measurement_frame_rpy_rad": [0.02, -0.01, 1.5],
    "measurement_noise_m": 3e-4,
}
FRAME = MeasurementFrame(
    tuple(TWIN["measurement_frame_position_m"]), tuple(TWIN["measurement_frame_rpy_rad"])
)
GOALS_M = ([0.03, 0.0, -0.25], [-0.04, 0.05, -0.22], [0.0, -0.06, -0.28])
POSES = 48
SAMPLES = 30  # measurements averaged per landing (noise 0.3 mm / sqrt(30) per axis)
PATIENT = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}  # a loaded 2-core machine
RUN_S = 900.0


@pytest.fixture(scope="module")
def config(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("config") / "robot.toml"
    path.write_text("[server]\nhttp_port = 8123\n")  # other sections must survive
    return path


@pytest.fixture(scope="module")
def client(tmp_path_factory, config):
    folder = tmp_path_factory.mktemp("cal")
    with make_client(
        folder,
        "sim",
        config_path=config,
        hardware={"sim": TWIN},
        safety=PATIENT,
        control={"gravity_compensation": True},
    ) as c:
        take_lease(c)
        yield c


def _status(client) -> dict:
    return ok_json(client.get("/api/status"))


def _landed_m(client, goal) -> float:
    """Send ``goal``, wait until the robot holds it, and return how far from it the
    platform is [m] by the twin's measurement (averaged, in the base frame)."""
    settle_at(client, goal)
    seen: list[np.ndarray] = []
    last = [-1]

    def sampled() -> bool:
        status = _status(client)
        if status["loop"]["ticks"] != last[0]:
            last[0] = status["loop"]["ticks"]
            seen.append(FRAME.to_base(status["ee"]["external_m"]))
        return len(seen) >= SAMPLES

    wait_for(sampled, f"{SAMPLES} measurements at {goal}")
    return float(np.linalg.norm(np.mean(seen, axis=0) - goal))


def _finished(client, run_id: str) -> dict:
    def ended():
        body = ok_json(client.get(f"/api/calibration/{run_id}"))
        return body if body["state"] in ("done", "refused", "failed") else None

    return wait_for(
        ended,
        f"calibration run {run_id} to end",
        RUN_S,
        poll_s=0.5,
        seen=lambda: ok_json(client.get(f"/api/calibration/{run_id}"))["progress"],
    )


@pytest.mark.slow
def test_after_a_geometry_fit_is_applied_goals_land_where_they_were_sent(client, config):
    client.post("/api/reset")
    torque_on(client)
    before = [_landed_m(client, goal) for goal in GOALS_M]
    assert min(before) > 2e-3, before  # millimetres off with the drawn robot

    run_id = ok_json(
        client.post("/api/calibration/run", json={"poses": POSES, "parameters": "geometry"})
    )["run_id"]
    body = _finished(client, run_id)
    assert body["state"] == "done", body
    assert body["holdout_rmse_m"] < 5e-4 < 2e-3 < body["holdout_rmse_before_m"], body

    applied = ok_json(client.post(f"/api/calibration/{run_id}/apply"))
    assert applied["parameters_applied"] == "geometry"
    assert applied["robot"]["kind"] == "per-leg" and applied["robot"]["version"] == 1
    after = [_landed_m(client, goal) for goal in GOALS_M]
    assert max(after) < 5e-4, (before, after, body["parameters"])

    # the config holds the fitted robot; read back, it is the controller's model
    assert applied["config_written"] == str(config)
    written = load_settings(config)
    robot = written.robot.build()
    assert isinstance(robot, PerLegRotaryDelta)
    assert robot == client.app.state.controller.robot
    assert written.server.http_port == 8123

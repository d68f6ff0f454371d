"""The telemetry message carries what the plots can show: the leg servos' current and PWM
as the tick read them, and in a hold the drone's pose the hold works from."""

from __future__ import annotations

import numpy as np
import pytest

from app.control.state import Snapshot, unread
from app.server.api import serialize
from app.server.api.responses import TelemetryMessage
from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for


def test_current_and_pwm_are_the_ticks_own_readings():
    readings = unread()
    readings["current_a"] = np.array([0.25, -0.5, np.nan])
    readings["pwm"] = np.array([0.1, -0.2, 0.3])
    message = serialize.telemetry(Snapshot(readings=readings))
    assert message["current_a"] == [0.25, -0.5, None]  # unknown is null, not NaN
    assert message["pwm"] == [0.1, -0.2, 0.3]
    TelemetryMessage.model_validate(message)  # the schema /openapi.json gives


def test_in_a_hold_the_world_frame_has_the_drone_pose():
    pose = [0.1, -0.2, 1.5, 1.0, 0.0, 0.0, 0.0]
    extra = {
        "goal_world_m": [0.1, 0.0, 1.2],
        "measured_world_m": [0.1, 0.0, 1.19],
        "drone_pose": pose,
    }
    message = serialize.telemetry(Snapshot(extra=extra))
    assert message["world"]["drone_pose"] == pose
    assert message["world"]["error_m"] == pytest.approx([0.0, 0.0, 0.01])
    TelemetryMessage.model_validate(message)


def test_get_telemetry_answers_current_and_pwm_per_leg(tmp_path):
    with make_client(tmp_path) as client:
        body = ok_json(client.get("/api/telemetry"))
    assert len(body["current_a"]) == 3 and len(body["pwm"]) == 3


@pytest.mark.slow  # an end-to-end hold run of seconds
def test_a_hold_run_streams_the_drone_pose_it_works_from(tmp_path):
    with make_client(tmp_path) as client:
        take_lease(client)
        client.post("/api/reset")
        ok_json(client.post("/api/torque", json={"enabled": True}))
        run_id = ok_json(client.post("/api/tests/hold", json={"duration_s": 2.0, "seed": 1}))[
            "run_id"
        ]
        with client.websocket_connect("/api/telemetry?hz=50") as ws:
            for _ in range(400):
                message = ws.receive_json()
                if message["world"] is not None and message["world"]["drone_pose"]:
                    break
        pose = message["world"]["drone_pose"]
        assert len(pose) == 7  # x, y, z [m], then a unit quaternion (w, x, y, z)
        assert np.linalg.norm(pose[3:]) == pytest.approx(1.0, abs=1e-6)
        assert 0.5 < pose[2] < 5.0  # the simulated drone hovers metres up
        TelemetryMessage.model_validate(message)
        wait_for(lambda: ok_json(client.get(f"/api/runs/{run_id}"))["state"] != "running", "run")

"""Calibration measured by motion capture through the pose input (issue 20).

The twin is built with joint offsets of a few degrees and a measurement frame turned and
moved from the base, with 0.3 mm of noise; a motion-capture system (tests/support/mocap.py)
streams its view of the platform to the server's UDP pose input as body "platform", in a
world frame shifted from the twin's own ``ee.external_m`` by SHIFT_M. A run with
``measurement: "pose-input"`` must find the offsets within 0.1 deg, bring the held-out
RMSE under 0.5 mm, and fit the stream's frame (so it measured the stream, not
``ee.external_m``). Without a fresh stream it must not start, and a stream that stops
must end the run with a reason, the arm holding.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from kinematics.identification import MeasurementFrame
from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.mocap import TwinMocap, free_udp_port
from tests.support.wait import ok_json, wait_for

TRUE_OFFSETS_RAD = tuple(math.radians(d) for d in (3.0, -2.0, 2.5))
TWIN_FRAME = MeasurementFrame((0.1, -0.05, -0.5), (0.02, -0.01, 1.5))
TWIN = {
    "true_joint_offsets_rad": list(TRUE_OFFSETS_RAD),
    "measurement_frame_position_m": list(TWIN_FRAME.position_m),
    "measurement_frame_rpy_rad": list(TWIN_FRAME.rpy_rad),
    "measurement_noise_m": 3e-4,
}
SHIFT_M = (0.2, -0.1, 0.05)  # the stream's world frame against the twin's own capture
PATIENT = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}
RUN_S = 600.0  # a loaded 2-core machine moves the twin slower than real time


@pytest.fixture(scope="module")
def port() -> int:
    return free_udp_port()


@pytest.fixture(scope="module")
def client(tmp_path_factory, port):
    folder = tmp_path_factory.mktemp("mocap")
    with make_client(
        folder, "sim", hardware={"sim": TWIN}, safety=PATIENT, world={"udp_port": port}
    ) as c:
        take_lease(c)
        yield c


@pytest.fixture
def mocap(client, port) -> TwinMocap:
    return TwinMocap(client.app.state.backend.bus, port, shift_m=SHIFT_M)


def _ready(client) -> None:
    client.post("/api/reset")
    torque_on(client)


def _state(client, run_id: str) -> dict:
    return ok_json(client.get(f"/api/calibration/{run_id}"))


def _ended(client, run_id: str) -> dict:
    return wait_for(
        lambda: (
            (b := _state(client, run_id))["state"] not in ("planned", "moving", "fitting") and b
        ),
        f"calibration run {run_id} to end",
        RUN_S,
        poll_s=0.5,
        seen=lambda: _state(client, run_id)["progress"],
    )


def _marker(client) -> dict:
    return ok_json(client.get("/api/mav/pose?body=platform"))


def _marker_fresh(client) -> bool:
    return _marker(client)["state"] == "ok"


def _stream_up(client, accepted_before: int) -> None:
    """Waits until the server keeps this stream's samples (not a last one of the one
    before, still fresh for stale_after_s after a previous test stopped streaming)."""
    wait_for(
        lambda: (m := _marker(client))["state"] == "ok" and m["accepted"] > accepted_before + 10,
        "the marker's stream",
        seen=lambda: _marker(client),
    )


@pytest.mark.slow  # the twin, through a calibration
def test_without_a_fresh_stream_the_run_does_not_start(client) -> None:
    _ready(client)
    assert not _marker_fresh(client)
    response = client.post("/api/calibration/run", json={"poses": 16, "measurement": "pose-input"})
    assert response.status_code == 409, response.text
    assert "measurement" in response.json()["detail"]
    assert ok_json(client.get("/api/status"))["mode"] == "idle"
    bad = client.post(
        "/api/calibration/run",
        json={"poses": 16, "source": "probe", "plate_z_m": -0.3, "measurement": "pose-input"},
    )
    assert bad.status_code == 422 and "measurement" in bad.text


@pytest.mark.slow
def test_a_run_measured_by_the_stream_recovers_the_offsets(client, mocap) -> None:
    _ready(client)
    accepted = _marker(client)["accepted"]
    with mocap.streaming():
        _stream_up(client, accepted)
        run_id = ok_json(
            client.post("/api/calibration/run", json={"poses": 16, "measurement": "pose-input"})
        )["run_id"]
        body = _ended(client, run_id)
    assert body["state"] == "done" and body["measurement"] == "pose-input", body
    error_deg = np.degrees(np.array(body["parameters"]["joint_offsets_rad"]) - TRUE_OFFSETS_RAD)
    assert np.all(np.abs(error_deg) < 0.1), (error_deg, body)
    assert body["holdout_rmse_before_m"] > 2e-3 and body["holdout_rmse_m"] < 5e-4, body
    # the fitted frame is the stream's: y + s = Rm^T (P - (tm - Rm s))
    fitted = MeasurementFrame(**body["measurement_frame"])
    streamed = np.array(TWIN_FRAME.position_m) - TWIN_FRAME.rotation @ np.array(SHIFT_M)
    assert np.linalg.norm(np.array(fitted.position_m) - streamed) < 3e-3, (fitted, streamed)
    np.testing.assert_allclose(fitted.rpy_rad, TWIN_FRAME.rpy_rad, atol=5e-3)


@pytest.mark.slow
def test_a_stream_that_stops_ends_the_run_with_its_reason(client, mocap) -> None:
    _ready(client)
    accepted = _marker(client)["accepted"]
    with mocap.streaming():
        _stream_up(client, accepted)
        run_id = ok_json(
            client.post("/api/calibration/run", json={"poses": 16, "measurement": "pose-input"})
        )["run_id"]
        wait_for(lambda: _state(client, run_id)["progress"]["pose"] >= 1, "a first pose", RUN_S)
    body = _ended(client, run_id)
    assert body["state"] == "failed" and "motion-capture" in body["error"], body
    assert "pairs.csv" in body["files"], body  # what it measured is kept
    status = ok_json(client.get("/api/status"))
    assert status["mode"] == "idle" and status["torque"], status  # holding, free again
    assert ok_json(client.get("/api/calibration"))[0]["run_id"] == run_id

"""The guided calibration end to end on the twin built wrong on purpose (issue 20).

The twin's joints are offset by a few degrees from what its encoders report, its motion
capture sits in a measurement frame turned and moved away from the base, with 0.3 mm of
noise. A calibration run through the API must find the offsets within 0.1 deg and bring
the held-out RMSE under 0.5 mm from several mm; applying it must make the controller's FK
of its measured joints agree with the measurement.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from app.config import load_settings
from hardware.calibration import JointCalibration
from hardware.encoder import RAD_PER_TICK
from kinematics import THESIS_DELTA
from kinematics.identification import MeasurementFrame
from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

TRUE_OFFSETS_RAD = tuple(math.radians(d) for d in (3.0, -2.0, 2.5))
TWIN = {
    "true_joint_offsets_rad": list(TRUE_OFFSETS_RAD),
    "measurement_frame_position_m": [0.1, -0.05, -0.5],
    "measurement_frame_rpy_rad": [0.02, -0.01, 1.5],
    "measurement_noise_m": 3e-4,
}
# What this test looks at is the fit, not the loop's health: a simulator starved on a
# loaded 2-core machine may stall or lag for up to 5 s without faulting the run half-way
# (as the page tests' servers; tests/control/ tests those faults).
PATIENT = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}
RUN_S = 600.0  # a loaded 2-core machine moves the twin slower than real time


@pytest.fixture(scope="module")
def config(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("config") / "robot.toml"
    path.write_text("[server]\nhttp_port = 8123\n")  # other sections must survive
    return path


@pytest.fixture(scope="module")
def client(tmp_path_factory, config):
    folder = tmp_path_factory.mktemp("cal")
    with make_client(
        folder, "sim", config_path=config, hardware={"sim": TWIN}, safety=PATIENT
    ) as c:
        take_lease(c)
        yield c


def _status(client) -> dict:
    return ok_json(client.get("/api/status"))


def _torque_on(client) -> None:
    client.post("/api/reset")
    torque_on(client)  # once the relaxed arm has come to rest inside its limits


def _finished(client, run_id: str) -> dict:
    def ended():
        body = ok_json(client.get(f"/api/calibration/{run_id}"))
        return body if body["state"] in ("done", "refused", "failed") else None

    return wait_for(
        ended,
        f"calibration run {run_id} to end",
        RUN_S,
        poll_s=0.5,
        seen=lambda: (
            {k: _status(client)[k] for k in ("mode", "torque", "faults", "warning")}
            | {"run": ok_json(client.get(f"/api/calibration/{run_id}"))["progress"]}
        ),
    )


def _records(joints) -> list[JointCalibration]:
    return [joint.calibration() for joint in joints]


def _fk_miss_m(client, frame: MeasurementFrame) -> float:
    """|FK(measured joints) in the measurement frame - the measurement| [m] now."""
    status = _status(client)
    joints = np.array(status["joints"]["position_rad"])
    seen = np.array(status["ee"]["external_m"])
    return float(np.linalg.norm(frame.from_base(THESIS_DELTA.fk(joints).points) - seen))


@pytest.mark.slow
def test_a_run_recovers_the_offsets_and_apply_makes_fk_agree(client, config) -> None:
    _torque_on(client)
    run_id = ok_json(
        client.post("/api/calibration/run", json={"poses": 24, "parameters": "offsets"})
    )["run_id"]
    planned = ok_json(client.get(f"/api/calibration/{run_id}"))
    # the observability is known before the arm moves (and here it is well conditioned)
    assert 1.0 <= planned["condition_number"] < 20.0, planned
    assert planned["unobservable"] == [] and len(planned["singular_values"]) == 9
    body = _finished(client, run_id)
    assert body["state"] == "done", body
    found = np.array(body["parameters"]["joint_offsets_rad"])
    error_deg = np.degrees(found - TRUE_OFFSETS_RAD)
    assert np.all(np.abs(error_deg) < 0.1), (error_deg, body)
    assert body["rmse_before_m"] > 2e-3, body  # several mm before
    assert body["holdout_rmse_before_m"] > 2e-3, body
    assert body["holdout_rmse_m"] < 5e-4, body
    assert body["rmse_after_m"] < 5e-4, body
    assert {"report.png", "pairs.csv", "result.json"} <= set(body["files"])
    png = client.get(f"/api/calibration/{run_id}/report.png")
    assert png.status_code == 200 and png.content.startswith(b"\x89PNG")

    # apply: the FK of what the controller measures now matches the measurement
    frame = MeasurementFrame(**body["measurement_frame"])
    before = np.median([_fk_miss_m(client, frame) for _ in range(5)])
    applied = ok_json(client.post(f"/api/calibration/{run_id}/apply"))
    np.testing.assert_allclose(applied["joint_offsets_rad"], found)
    # the config file in use now holds zero offsets that read the same ticks as q + o
    assert applied["config_written"] == str(config)
    written = load_settings(config)
    assert written.server.http_port == 8123
    nominal = load_settings().hardware.joints
    for old, new, offset in zip(
        _records(nominal), _records(written.hardware.joints), found, strict=True
    ):
        assert math.isclose(new.to_rad(2000), old.to_rad(2000) + offset, abs_tol=RAD_PER_TICK)
    after = np.median([_fk_miss_m(client, frame) for _ in range(5)])
    assert before > 2e-3 and after < 1e-3, (before, after)
    again = client.post(f"/api/calibration/{run_id}/apply")
    assert again.status_code == 409 and "applied" in again.json()["detail"]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"poses": 5}, "poses"),
        ({"poses": 10_000}, "poses"),
        ({"poses": "30"}, "poses"),
        ({"parameters": "everything"}, "parameters"),
        ({"poses": 30, "speed": 2}, "speed"),
    ],
)
def test_bad_input_is_422_naming_the_field_and_moves_nothing(client, body, field) -> None:
    _torque_on(client)
    response = client.post("/api/calibration/run", json=body)
    assert response.status_code == 422, response.text
    assert field in response.json()["detail"]
    assert _status(client)["mode"] == "idle"


def test_torque_off_is_409(client) -> None:
    ok_json(client.post("/api/torque", json={"enabled": False}))
    response = client.post("/api/calibration/run", json={"poses": 20})
    assert response.status_code == 409 and "torque" in response.json()["detail"]


def test_an_unknown_run_is_404(client) -> None:
    assert client.get("/api/calibration/cal-nothing").status_code == 404
    assert client.post("/api/calibration/cal-nothing/apply").status_code == 404

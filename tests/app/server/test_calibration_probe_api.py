"""Probe calibration through the API on the twin built wrong on purpose (issue 20).

The twin's joints are offset by a few degrees from what its encoders report and there is
no motion capture to use: the run touches a flat plate of known height (the twin's touches
come from its true model) and fits from heights alone. It must find the offsets within
0.1 deg, say what heights cannot pin, and, once applied, a second run finds nothing left.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

TRUE_OFFSETS_RAD = tuple(math.radians(d) for d in (3.0, -2.0, 2.5))
PLATE_M = -0.25
PATIENT = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}  # a loaded machine
RUN_S = 300.0


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    folder = tmp_path_factory.mktemp("probe")
    twin = {"true_joint_offsets_rad": list(TRUE_OFFSETS_RAD)}
    with make_client(folder, "sim", hardware={"sim": twin}, safety=PATIENT) as c:
        take_lease(c)
        yield c


def _start(client, **body) -> str:
    client.post("/api/reset")
    torque_on(client)
    return ok_json(client.post("/api/calibration/run", json=body))["run_id"]


def _finished(client, run_id: str) -> dict:
    def ended():
        body = ok_json(client.get(f"/api/calibration/{run_id}"))
        return body if body["state"] in ("done", "refused", "failed") else None

    return wait_for(ended, f"probe run {run_id} to end", RUN_S, poll_s=0.2)


@pytest.mark.slow  # a probing run on the twin
def test_a_probe_run_finds_the_offsets_and_after_apply_nothing_is_left(client) -> None:
    run_id = _start(client, poses=32, parameters="offsets", source="probe", plate_z_m=PLATE_M)
    planned = ok_json(client.get(f"/api/calibration/{run_id}"))
    assert planned["source"] == "probe" and planned["plate_z_m"] == PLATE_M
    assert planned["unobservable"] == [] and len(planned["singular_values"]) == 3
    body = _finished(client, run_id)
    assert body["state"] == "done", body
    found = np.array(body["parameters"]["joint_offsets_rad"])
    error_deg = np.degrees(found - TRUE_OFFSETS_RAD)
    assert np.all(np.abs(error_deg) < 0.1), (error_deg, body)
    assert body["holdout_rmse_before_m"] > 1e-3 > 1e-4 > body["holdout_rmse_m"], body
    assert {"report.png", "touches.csv", "result.json"} <= set(body["files"])
    assert client.get(f"/api/calibration/{run_id}/touches.csv").status_code == 200

    applied = ok_json(client.post(f"/api/calibration/{run_id}/apply"))
    np.testing.assert_allclose(applied["joint_offsets_rad"], found)
    # the controller now reads q + o: a second probe run finds the touches where the
    # model says, and nothing more to correct
    again = _finished(
        client, _start(client, poses=32, source="probe", plate_z_m=PLATE_M, parameters="offsets")
    )
    assert again["holdout_rmse_before_m"] < 1e-4, again
    left_deg = np.degrees(again["parameters"]["joint_offsets_rad"])
    assert np.all(np.abs(left_deg) < 0.1), left_deg


@pytest.mark.slow
def test_a_geometry_probe_run_says_what_heights_cannot_pin(client) -> None:
    run_id = _start(
        client, poses=60, parameters="geometry", source="probe", plate_z_m=PLATE_M, fit_plate_z=True
    )
    planned = ok_json(client.get(f"/api/calibration/{run_id}"))
    # one plate, its height free: the SVD finds directions no touch can see
    assert "plate_z" in planned["unobservable"], planned
    assert planned["unobservable_combinations"], planned
    assert planned["condition_number"] is None or planned["condition_number"] > 1e6
    body = _finished(client, run_id)
    assert body["state"] in ("done", "refused"), body
    assert body["plate_error_m"] is not None
    apply = client.post(f"/api/calibration/{run_id}/apply")
    assert apply.status_code == 409  # a geometry fit is never applied


@pytest.mark.slow
@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"poses": 20, "source": "probe"}, "plate_z_m"),
        ({"poses": 20, "source": "probe", "plate_z_m": 250}, "plate_z_m"),
        ({"poses": 20, "source": "probe", "plate_z_m": -5.0}, "plate_z_m"),
        ({"poses": 20, "plate_z_m": -0.25}, "plate_z_m"),
        ({"poses": 20, "source": "laser"}, "source"),
        ({"poses": 20, "source": "probe", "plate_z_m": -0.25, "parameters": "geometry"}, "poses"),
    ],
)
def test_bad_probe_input_is_422_naming_the_field(client, body, field) -> None:
    client.post("/api/reset")
    torque_on(client)
    response = client.post("/api/calibration/run", json=body)
    assert response.status_code == 422, response.text
    assert field in str(response.json()["detail"])

"""The default backend, the MuJoCo twin: the server drives it like real servos."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import load_settings
from tests.support.app_client import make_client, settle_at, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for


@pytest.mark.slow  # end to end on the twin
def test_default_backend_is_the_twin_and_reaches_a_goal(tmp_path):
    assert load_settings().hardware.backend == "sim"
    with make_client(tmp_path, backend="sim") as client:
        take_lease(client)
        status = ok_json(client.get("/api/status"))
        assert status["backend"] == "sim" and status["mode"] == "idle"
        # torque off: the arm falls and hangs under gravity
        wait_for(
            lambda: ok_json(client.get("/api/status"))["ee"]["position_m"][2] < -0.3,
            "the relaxed arm to hang",
        )
        torque_on(client)  # accepted once the arm is back inside its joint limits
        goal = [0.02, -0.01, -0.23]
        response = client.post("/api/goal", json={"position_m": goal})
        assert response.status_code == 200, response.text

        def near_goal() -> bool:
            measured = ok_json(client.get("/api/status"))["ee"]["position_m"]
            # P-only factory gains leave a small sag under gravity: within 3 mm
            return np.linalg.norm(np.subtract(measured, goal)) < 0.003

        wait_for(near_goal, "the twin to reach the goal")

        def lifting() -> bool:
            # theta is positive downwards, so holding the arm up against gravity takes a
            # negative current on every joint once the approach has settled (in transit
            # a joint may brake with either sign, or read zero)
            return all(c < 0.0 for c in ok_json(client.get("/api/status"))["joints"]["current_a"])

        wait_for(lifting, "every servo to hold the arm against gravity")


@pytest.mark.slow  # an end-to-end run of seconds on the twin
def test_sinusoid_on_the_twin_has_tracking_and_validation_stats(tmp_path):
    """On the simulator the twin's true platform is the external measurement (thesis
    Table 6.2): FK of the encoders agrees with it to encoder resolution."""
    # the stats of a finished run are the point here, not the faults a starved simulator
    # trips (tests/control tests those): allow it a 5 s stall or lag
    patient = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}
    with make_client(tmp_path, backend="sim", safety=patient) as client:
        take_lease(client)
        # a defined pose first: after torque on the twin's arm may still be falling
        settle_at(client, [0.0, 0.0, -0.24])
        external = ok_json(client.get("/api/status"))["ee"]["external_m"]
        assert None not in external
        run_id = ok_json(client.post("/api/tests/sinusoid", json={"duration_s": 1.5}))["run_id"]
        run = wait_for(lambda: _ended(client, run_id), f"run {run_id} to end")
        assert run["state"] == "done", run
        stats = run["stats"]
    for axis in "xyz":
        assert stats["validation"][axis]["max_abs_m"] < 0.001
        assert stats["tracking"][axis]["rmse_m"] > stats["validation"][axis]["rmse_m"]


def _ended(client: TestClient, run_id: str) -> dict | None:
    """The run's record once it is no longer running, else None."""
    run = ok_json(client.get(f"/api/runs/{run_id}"))
    return run if run["state"] != "running" else None

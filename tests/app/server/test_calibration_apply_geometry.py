"""POST /api/calibration/{run_id}/apply of a geometry fit, on the emulated bus: the
controller's robot model becomes the fitted per-leg one for every route that computes with
it, nothing moves, the config file gets [robot.legs], and it is refused while a motion runs.

The runs here are fitted from exact pairs of a robot whose rods are 1.5 to 2.5 mm short
(so the fit is that robot) and put in the calibration manager as a finished run would be;
tests/app/server/test_calibration_api.py does the whole procedure on the twin.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.calibration.fit import fit, plan
from app.calibration.procedure import CalibrationRun
from app.config import load_settings
from app.server import sections
from app.server.api.runs import WaypointsRequest
from app.world.drone_sim import DroneSimParams
from kinematics import THESIS_DELTA, PerLegRotaryDelta
from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

NOMINAL = PerLegRotaryDelta.from_symmetric(THESIS_DELTA)
SHORT_RODS = NOMINAL.with_values(l=(0.2410, 0.2415, 0.2405))
CENTRE_M = np.array([0.0, 0.0, -0.24])


@pytest.fixture(scope="module")
def config(tmp_path_factory):
    path = tmp_path_factory.mktemp("config") / "robot.toml"
    path.write_text("[server]\nhttp_port = 8123\n")  # other sections must survive
    return path


@pytest.fixture(scope="module")
def client(tmp_path_factory, config):
    with make_client(tmp_path_factory.mktemp("runs"), config_path=config) as c:
        take_lease(c)
        yield c


def _done_run(client, true: PerLegRotaryDelta, run_id: str) -> CalibrationRun:
    """A geometry run fitted to exact pairs of ``true``, done, as the manager keeps one."""
    manager = client.app.state.calibration
    chosen = plan(NOMINAL, 40, "geometry")
    measured = true.fk(chosen.joints).points
    result = fit(NOMINAL, chosen.joints, measured, len(chosen.holdout_joints), "geometry")
    folder = manager.folder / run_id
    folder.mkdir(parents=True, exist_ok=True)
    run = CalibrationRun(run_id, "geometry", 40, chosen, folder, state="done", result=result)
    run.nominal = NOMINAL
    run.model_version = client.app.state.controller.model.version
    manager._runs[run_id] = run
    return run


def _status(client) -> dict:
    return ok_json(client.get("/api/status"))


def _nearest(client, point) -> dict:
    x, y, z = point
    return ok_json(client.get(f"/api/workspace/nearest?x_m={x}&y_m={y}&z_m={z}"))


def _section(client) -> np.ndarray:
    """GET /api/workspace/section of the xz plane at y = 0: the cells the gate takes."""
    body = ok_json(client.get("/api/workspace/section?plane=xz&at_m=0"))
    return np.array([[c == "1" for c in row] for row in body["reachable"]])


def _to(point) -> str:
    """A program that goes straight to ``point`` [m] (millimetres, base frame)."""
    x, y, z = (1e3 * v for v in point)
    return f"G21 G90\nG1 X{x:.4f} Y{y:.4f} Z{z:.4f} F600\n"


def _program(client, gcode: str) -> dict:
    """POST /api/programs/check from 60 mm above the program's end: the report."""
    start = [0.0, 0.0, float(gcode.split("Z")[1].split()[0]) * 1e-3 + 0.06]
    return ok_json(client.post("/api/programs/check", json={"gcode": gcode, "start_m": start}))


def _bottom(client) -> np.ndarray:
    """The lowest goal the nominal robot accepts below the centre, 0.3 mm inside it."""
    lowest = np.array(_nearest(client, [0.0, 0.0, -0.9])["nearest_m"])
    return lowest + 3e-4 * (CENTRE_M - lowest) / np.linalg.norm(CENTRE_M - lowest)


@pytest.mark.slow  # a motion on the twin
def test_apply_is_refused_while_a_motion_runs_and_changes_nothing(client, config) -> None:
    torque_on(client)
    _done_run(client, SHORT_RODS, "cal-moving")
    ok_json(client.post("/api/move", json={"position_m": [0.03, 0.0, -0.25], "duration_s": 3.0}))
    wait_for(lambda: _status(client)["mode"] == "move", "the move to start")
    response = client.post("/api/calibration/cal-moving/apply")
    assert response.status_code == 409 and "rests" in response.json()["detail"], response.text
    info = ok_json(client.get("/api/info"))["robot"]
    assert info["kind"] == "symmetric" and info["version"] == 0
    assert "legs" not in config.read_text()
    wait_for(lambda: _status(client)["mode"] == "idle", "the move to end", 30.0)
    client.app.state.calibration._runs.pop("cal-moving")


@pytest.mark.slow
def test_a_geometry_fit_becomes_the_model_of_every_route_and_nothing_moves(client, config):
    torque_on(client)
    wait_for(lambda: _status(client)["mode"] == "idle", "the arm to rest")
    bottom = _bottom(client)
    assert _nearest(client, bottom)["inside"]  # the nominal robot takes it
    run = _done_run(client, SHORT_RODS, "cal-geometry")
    stale = _done_run(client, SHORT_RODS, "cal-stale")  # also fitted against the nominal
    fitted = run.result.robot
    for name in ("L", "l", "R"):  # exact pairs: the fit is the short-rod robot (R - r seen)
        np.testing.assert_allclose(getattr(fitted, name), getattr(SHORT_RODS, name), atol=1e-7)
    before = _status(client)
    section_before = _section(client)
    gcode = _to(bottom)
    assert _program(client, gcode)["ok"] is True  # the nominal robot takes the program
    waypoints = {"points_m": [[0.0, 0.0, -0.30], bottom.tolist()], "times_s": [0.0, 2.0]}
    nominal = client.app.state.controller.model
    client.app.state.runs.plan(WaypointsRequest(**waypoints).params(), nominal)  # and the run

    applied = ok_json(client.post("/api/calibration/cal-geometry/apply"))
    assert applied["parameters_applied"] == "geometry"
    model = applied["robot"]
    assert model["kind"] == "per-leg" and model["version"] == 1
    assert model["origin"] == "calibration cal-geometry"
    np.testing.assert_allclose(model["l_m"], fitted.l, atol=1e-12)
    assert ok_json(client.get("/api/info"))["robot"] == model

    # nothing moved: the same joints, now at the new robot's FK point
    after = _status(client)
    np.testing.assert_allclose(
        after["joints"]["commanded_rad"], before["joints"]["commanded_rad"], atol=1e-9
    )
    np.testing.assert_allclose(
        after["ee"]["commanded_m"],
        fitted.fk(after["joints"]["commanded_rad"]).points,
        atol=1e-9,
    )

    # the workspace views, the goal's gate and its nearest point are the fitted robot's
    seen = _nearest(client, bottom)
    assert not seen["inside"] and seen["distance_m"] > 1e-3, seen
    refused = client.post("/api/goal", json={"position_m": bottom.tolist()})
    assert refused.status_code == 422 and "position_m" in refused.text, refused.text
    section = _section(client)
    assert section.sum() < section_before.sum()  # shorter rods: a smaller workspace
    expected = sections.section(client.app.state.controller.gate, "xz", 0.0).reachable
    np.testing.assert_array_equal(section, expected)

    # a program's check and a run's feasibility check are the fitted robot's
    report = _program(client, gcode)
    assert not report["ok"] and {v["kind"] for v in report["violations"]} >= {"workspace"}
    response = client.post("/api/tests/waypoints", json=waypoints)
    assert response.status_code == 422 and "outside the workspace" in response.text
    assert _status(client)["mode"] == "idle"
    # hold-in-world (the robot node's) clamps its goals with the gate of the model in use
    world = client.app.state.node.world.service
    hold = world.hold_source(np.zeros(3), world.provider(DroneSimParams()), False)
    assert hold.gate.robot == client.app.state.controller.robot and not hold.gate.inside(bottom)

    # the config file holds the legs, read back as the same robot
    assert applied["config_written"] == str(config)
    written = load_settings(config)
    assert written.server.http_port == 8123
    assert written.robot.build() == client.app.state.controller.robot

    again = client.post("/api/calibration/cal-geometry/apply")
    assert again.status_code == 409 and "applied" in again.json()["detail"]
    # a run that started before this apply was fitted against the nominal robot
    response = client.post(f"/api/calibration/{stale.run_id}/apply")
    assert response.status_code == 409 and "calibrate again" in response.json()["detail"]

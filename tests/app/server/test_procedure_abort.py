"""One mover at a time: while a calibration or tuning procedure runs on the twin, every
route that would start a motion is refused (409, naming the procedure and its abort
route), e-stop still stops; the procedure's abort route stops its motion at once, ends it
"aborted" and frees the robot (app/control/owner.py)."""

from __future__ import annotations

import pytest

from tests.support.app_client import make_client, settle_at, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

# the robot's moves, not the loop's health, are what these tests look at: a simulator
# starved on a loaded 2-core machine may stall or lag without faulting the procedure
PATIENT = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}
WAIT_S = 120.0
REST = [0.0, 0.0, -0.25]
PROGRAM = "G21 G90\nG1 F600 X5\nM2\n"
# every route that starts a motion or a run, with a body it would otherwise accept
MOTIONS = [
    ("/api/tests/sinusoid", {}),
    ("/api/tests/step", {}),
    ("/api/tests/chirp", {}),
    ("/api/tests/waypoints", {"points_m": [REST, [0.0, 0.0, -0.24]], "times_s": [0.0, 1.0]}),
    ("/api/tests/hold", {}),
    ("/api/hold", {"frame": "current", "source": "simulated"}),
    ("/api/programs/run", {"gcode": PROGRAM}),
    ("/api/goal", {"position_m": REST}),
    ("/api/jog", {"delta_m": [0.001, 0.0, 0.0]}),
    ("/api/jog", {"velocity_m_s": [0.01, 0.0, 0.0]}),
    ("/api/move", {"position_m": REST}),
]


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    with make_client(tmp_path_factory.mktemp("abort"), "sim", safety=PATIENT) as c:
        take_lease(c)
        yield c


def _ready(client) -> None:
    """Reset, torque on and the arm at rest at REST: a procedure plans from where the arm
    is, and refuses to go on if it then moved (CI saw an arm still swinging after torque on
    move 23.7 mm between a tuning's plan and its first run)."""
    client.post("/api/reset")
    settle_at(client, REST)


def _status(client) -> dict:
    return ok_json(client.get("/api/status"))


def _refused_while(client, what: str, abort: str) -> None:
    """Every motion route answers 409 naming ``what`` and the ``abort`` route."""
    for path, body in MOTIONS:
        answer = client.post(path, json=body)
        assert answer.status_code == 409, (path, answer.status_code, answer.text)
        assert what in answer.text and abort in answer.text, (path, answer.text)


def _idle_and_free(client) -> None:
    """The robot holds still (no source) and takes a jog again."""
    assert _status(client)["mode"] == "idle"
    ok_json(client.post("/api/jog", json={"delta_m": [0.0005, 0.0, 0.0]}))


@pytest.mark.slow
def test_calibration_holds_the_robot_until_aborted(twin) -> None:
    _ready(twin)
    run_id = ok_json(twin.post("/api/calibration/run", json={"poses": 12}))["run_id"]
    abort = f"/api/calibration/{run_id}/abort"
    wait_for(
        lambda: ok_json(twin.get(f"/api/calibration/{run_id}"))["state"] == "moving",
        "the calibration to move",
        WAIT_S,
        seen=lambda: ok_json(twin.get(f"/api/calibration/{run_id}")),
    )
    _refused_while(twin, f"calibration run {run_id}", abort)
    answer = twin.post("/api/tuning/run", json={"joints": [1]})
    assert answer.status_code == 409 and run_id in answer.text, answer.text

    lease = twin.headers.pop("X-Lease")  # abort needs the lease, as starting does
    assert twin.post(abort).status_code == 409
    twin.headers["X-Lease"] = lease
    assert twin.post("/api/calibration/nope/abort").status_code == 404

    body = ok_json(twin.post(abort))
    assert body["state"] == "aborted" and "abort" in body["error"], body
    _idle_and_free(twin)
    manager = twin.app.state.calibration
    wait_for(lambda: not manager.running(), "the calibration's thread to end", WAIT_S)
    body = ok_json(twin.get(f"/api/calibration/{run_id}"))
    assert body["state"] == "aborted", body  # the thread's end does not overwrite it
    answer = twin.post(abort)
    assert answer.status_code == 409 and "aborted" in answer.text, answer.text

    listed = ok_json(twin.get("/api/calibration"))
    assert listed[0]["run_id"] == run_id and listed[0]["state"] == "aborted", listed


@pytest.mark.slow
def test_estop_stops_a_calibration_and_frees_the_robot(twin) -> None:
    _ready(twin)
    run_id = ok_json(twin.post("/api/calibration/run", json={"poses": 12}))["run_id"]
    ok_json(twin.post("/api/estop"))
    body = wait_for(
        lambda: (b := ok_json(twin.get(f"/api/calibration/{run_id}")))["state"] == "failed" and b,
        "the e-stopped calibration to fail",
        WAIT_S,
    )
    assert "e-stop" in body["error"], body
    wait_for(lambda: not twin.app.state.calibration.running(), "its thread to end", WAIT_S)
    answer = twin.post(f"/api/calibration/{run_id}/abort")
    assert answer.status_code == 409 and "failed" in answer.text, answer.text
    twin.post("/api/reset")
    torque_on(twin)
    _idle_and_free(twin)


@pytest.mark.slow
def test_tuning_holds_the_robot_between_its_runs_and_abort_stops_them(twin) -> None:
    _ready(twin)
    run_id = ok_json(twin.post("/api/tuning/run", json={"joints": [1, 2, 3]}))["run_id"]
    abort = f"/api/tuning/{run_id}/abort"
    body = wait_for(
        lambda: (b := ok_json(twin.get(f"/api/tuning/{run_id}")))["runs"] and b,
        "the tuning's step run to start",
        WAIT_S,
        seen=lambda: ok_json(twin.get(f"/api/tuning/{run_id}")),
    )
    _refused_while(twin, f"tuning run {run_id}", abort)
    answer = twin.post("/api/calibration/run", json={"poses": 12})
    assert answer.status_code == 409 and run_id in answer.text, answer.text
    assert twin.post("/api/tuning/nope/abort").status_code == 404

    body = ok_json(twin.post(abort))
    assert body["state"] == "aborted", body
    _idle_and_free(twin)
    manager = twin.app.state.tuning
    wait_for(lambda: not manager.running(), "the tuning's thread to end", WAIT_S)
    body = ok_json(twin.get(f"/api/tuning/{run_id}"))
    assert body["state"] == "aborted", body
    for kind, recorded in body["runs"].items():  # none goes on, and no chirp starts after
        # (a run's recorder closes its files and records its end in a thread of its own)
        wait_for(
            lambda recorded=recorded: (
                ok_json(twin.get(f"/api/runs/{recorded}"))["state"] != "running"
            ),
            f"the tuning's {kind} run recorded as ended",
            WAIT_S,
            seen=lambda recorded=recorded: ok_json(twin.get(f"/api/runs/{recorded}")),
        )
    assert all(r["state"] != "running" for r in ok_json(twin.get("/api/runs")))
    assert twin.post(abort).status_code == 409

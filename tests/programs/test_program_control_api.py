"""The program's motion control through the whole stack: the API (POST /api/programs/pause,
/resume, /step, PUT /feed, /optional-stop, POST /run with start_line, feed_override and
optional_stop), the run manager, the station's link client, the robot node (in-process:
signed ops, its snapshot) and its PathSource, on the emulated servos. The run's progress
in GET /api/runs carries paused, feed override, line and time left."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tests.support.app_client import cleared, make_client
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

# from where the robot rests (relative moves): line 2 moves 10 mm at 6 mm/s, line 3 is an
# M0, lines 4 and 5 move back, line 6 is an M1, line 7 a last short move
PROGRAM = "G21 G91 F360\nG1 X10\nM0\nG1 Y5\nG1 Y-5\nM1\nG1 X-10\nM2"


@pytest.fixture(scope="module")
def shared(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(tmp_path_factory.mktemp("runs")) as client:
        take_lease(client)
        yield client


@pytest.fixture
def fresh(shared: TestClient) -> Iterator[TestClient]:
    cleared(shared)
    ok_json(shared.post("/api/torque", json={"enabled": True}))
    yield shared
    for run in ok_json(shared.get("/api/runs")):  # leave no run going for the next test
        if run["state"] == "running":
            shared.post(f"/api/runs/{run['run_id']}/abort")


def _progress(client, run_id) -> dict:
    run = ok_json(client.get(f"/api/runs/{run_id}"))
    return run["progress"] or {"state": run["state"]}


def _goal(client) -> list[float]:
    return ok_json(client.get("/api/status"))["goal"]["position_m"]


def _start(client, **body) -> str:
    response = client.post("/api/programs/run", json={"gcode": PROGRAM, **body})
    assert response.status_code == 200, response.text
    return response.json()["run_id"]


@pytest.mark.slow  # seconds of a run
def test_m0_pauses_and_pause_feed_step_resume_steer_the_running_program(fresh):
    run_id = _start(fresh, feed_override=0.5)
    seen = lambda: _progress(fresh, run_id)  # noqa: E731
    first = wait_for(lambda: (p := seen()).get("program_line") == 2 and p, "line 2", seen=seen)
    assert first["feed_override"] == 0.5 and first["paused"] is None
    assert first["time_left_s"] > 0
    # the M0 on line 3 stops it there until Resume
    at_m0 = wait_for(
        lambda: (p := seen()).get("paused") == "M0 at line 3: press Resume" and p, "M0", seen=seen
    )
    assert at_m0["program_line"] == 3 and at_m0["feed_rate"] == 0.0
    goal = _goal(fresh)
    assert seen()["paused"] == at_m0["paused"] and _goal(fresh) == goal  # it waits
    # feed override while it stands: said back, time left at the new override
    state = ok_json(fresh.put("/api/programs/feed", json={"override": 1.0}))
    assert state["run_id"] == run_id and state["feed_override"] == 1.0
    assert state["time_left_s"] == pytest.approx(at_m0["time_left_s"] / 2, rel=0.02)
    # out of range: a 422 naming the field, and nothing changes
    refused = fresh.put("/api/programs/feed", json={"override": 1.5})
    assert refused.status_code == 422 and "override" in refused.text
    assert seen()["feed_override"] == 1.0
    # a single step: to the end of line 4, then it stands there
    assert ok_json(fresh.post("/api/programs/step"))["stop_line"] == 4
    stepped = wait_for(
        lambda: ((p := seen()).get("paused") or "").startswith("single step") and p,
        "the step's stop",
        seen=seen,
    )
    assert stepped["paused"] == "single step: stopped at the end of line 4"
    assert stepped["program_line"] == 4
    # resume, then pause mid-line 5: it stands on its path, the line stays
    ok_json(fresh.post("/api/programs/resume"))
    wait_for(lambda: seen().get("program_line") == 5, "line 5", seen=seen)
    assert ok_json(fresh.post("/api/programs/pause"))["paused"] in ("pausing", "paused")
    paused = wait_for(lambda: (p := seen()).get("paused") == "paused" and p, "paused", seen=seen)
    assert paused["program_line"] == 5
    goal = _goal(fresh)
    wait_for(lambda: ok_json(fresh.get("/api/status"))["loop"]["ticks"] > 0, "a tick")
    assert _goal(fresh) == goal and seen()["paused"] == "paused"
    # line 5 runs along y from (x0 + 10, y0 + 5) to (x0 + 10, y0): x stays, y between
    start = ok_json(fresh.get(f"/api/runs/{run_id}"))["params"]["start_m"]
    assert goal[0] == pytest.approx(start[0] + 0.01, abs=1e-9)
    assert start[1] - 1e-9 <= goal[1] <= start[1] + 0.005 + 1e-9
    # the optional stop switched off: M1 on line 6 goes by, the run ends
    ok_json(fresh.put("/api/programs/optional-stop", json={"on": False}))
    ok_json(fresh.post("/api/programs/resume"))
    wait_for(lambda: seen().get("state") == "done", "the run's end", seen=seen)


@pytest.mark.slow
def test_run_from_a_line_approaches_its_start_and_stops_at_m1_with_the_optional_stop(fresh):
    run_id = _start(fresh, start_line=4, optional_stop=True)
    seen = lambda: _progress(fresh, run_id)  # noqa: E731
    at_m1 = wait_for(
        lambda: ((p := seen()).get("paused") or "").startswith("M1") and p, "the M1", seen=seen
    )
    assert at_m1["paused"] == "M1 (optional stop) at line 6: press Resume"
    run = ok_json(fresh.get(f"/api/runs/{run_id}"))
    assert run["params"]["start_line"] == 4 and run["params"]["optional_stop"] is True
    # lines 4 and 5 go +5 mm then -5 mm in y from line 4's start, which is line 2's end:
    # 10 mm in x from where the robot was checked from (the approach went there first)
    # (the M1 falls between two loop samples, where the robot node interpolates: within
    # the jerk-limited path's travel over one period from rest, J dt^3 / 6 ~ 1e-6 m)
    where = np.array(run["params"]["start_m"])
    np.testing.assert_allclose(_goal(fresh), where + [0.01, 0.0, 0.0], atol=2e-6)
    ok_json(fresh.post("/api/programs/resume"))
    wait_for(lambda: seen().get("state") == "done", "the run's end", seen=seen)


def test_steering_with_no_program_running_is_a_409_and_bad_bodies_422(fresh):
    for route in ("pause", "resume", "step"):
        response = fresh.post(f"/api/programs/{route}")
        assert response.status_code == 409, response.text
        assert "no program is running" in response.json()["detail"]
    response = fresh.put("/api/programs/feed", json={"override": 0.5})
    assert response.status_code == 409
    for body, field in (({"override": 0.05}, "override"), ({"overide": 0.5}, "overide")):
        response = fresh.put("/api/programs/feed", json=body)
        assert response.status_code == 422 and field in response.text, response.text
    response = fresh.post("/api/programs/run", json={"gcode": PROGRAM, "start_line": 99})
    assert response.status_code == 422
    assert response.json()["detail"].startswith("start_line: line 99 is past the program's end")
    response = fresh.post("/api/programs/run", json={"gcode": PROGRAM, "feed_override": 1.2})
    assert response.status_code == 422 and "feed_override" in response.text
    assert all(r["state"] != "running" for r in ok_json(fresh.get("/api/runs")))


def test_without_the_lease_nothing_is_steered(fresh):
    response = fresh.post("/api/programs/pause", headers={"X-Lease": "not-mine"})
    assert response.status_code == 409, response.text
    response = fresh.put("/api/programs/feed", json={"override": 0.5}, headers={"X-Lease": "x"})
    assert response.status_code == 409, response.text

"""Runs end to end on the emulated bus: start, finish, stats, logs, report, abort, refusal."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
from mcap.reader import make_reader

from app.runs.logs import read_messages
from tests.support.wait import ok_json, wait_for

SHORT = {"duration_s": 1.5}


def _run(client, run_id):
    return ok_json(client.get(f"/api/runs/{run_id}"))


def _state(client, run_id):
    return _run(client, run_id)["state"]


@pytest.mark.slow  # an end-to-end run of seconds
def test_sinusoid_run_end_to_end(fresh):
    fresh.post("/api/torque", json={"enabled": True})
    response = fresh.post("/api/tests/sinusoid", json=SHORT)
    assert response.status_code == 200, response.text
    run_id = response.json()["run_id"]
    wait_for(
        lambda: _state(fresh, run_id) != "running",
        "the run to end",
        seen=lambda: _run(fresh, run_id),
    )
    run = ok_json(fresh.get(f"/api/runs/{run_id}"))
    assert run["state"] == "done" and run["params"]["duration_s"] == 1.5
    for axis in "xyz":
        stats = run["stats"]["tracking"][axis]
        assert all(np.isfinite(stats[k]) for k in ("mean_m", "rmse_m", "std_m", "max_abs_m"))
        assert 0.0 < stats["rmse_m"] < 0.2  # sanity; benchmarks/runs.py measures the figure
    mcap = fresh.get(f"/api/runs/{run_id}/log.mcap")
    assert mcap.status_code == 200
    messages = list(make_reader(io.BytesIO(mcap.content)).iter_messages())
    assert len(messages) == run["samples"] > 0  # every tick of the run, nothing dropped
    rows = list(csv.DictReader(io.StringIO(fresh.get(f"/api/runs/{run_id}/log.csv").text)))
    assert len(rows) == run["samples"] and {r["phase"] for r in rows} >= {"approach", "timed"}
    wait_for(  # drawn after the record is final, so it holds no next run back
        lambda: _run(fresh, run_id)["has_report"],
        "the report drawn",
        seen=lambda: _run(fresh, run_id),
    )
    png = fresh.get(f"/api/runs/{run_id}/report.png")
    assert png.status_code == 200, png.text
    assert png.content[:8] == b"\x89PNG\r\n\x1a\n"
    pdf = fresh.get(f"/api/runs/{run_id}/report.pdf")
    assert pdf.status_code == 200 and pdf.content[:5] == b"%PDF-", pdf.text[:200]
    assert run_id in [r["run_id"] for r in ok_json(fresh.get("/api/runs"))]


def test_infeasible_sinusoid_is_refused_before_any_motion(fresh):
    fresh.post("/api/torque", json={"enabled": True})
    before = ok_json(fresh.get("/api/status"))["joints"]["commanded_rad"]
    response = fresh.post("/api/tests/sinusoid", json={"amplitude_m": [0.3, 0.0, 0.0]})
    assert response.status_code == 422
    assert "infeasible" in response.json()["detail"] and "t = " in response.json()["detail"]
    status = ok_json(fresh.get("/api/status"))
    assert status["mode"] == "idle" and status["joints"]["commanded_rad"] == before


def test_bad_sinusoid_bodies_are_422(fresh):
    for body in (
        {"duration_s": -1},
        {"amplitude_m": [0.01, 0.01]},
        {"frequency_hz": [1, 1, 99]},
        {"offset_m": [0, 0, float("nan")]},
        {"wobble": 1},
    ):
        response = fresh.post(
            "/api/tests/sinusoid",
            content=json.dumps(body),
            headers={"content-type": "application/json"},
        )
        assert response.status_code == 422, body


@pytest.mark.slow  # an end-to-end run of seconds
def test_aborted_run_leaves_a_readable_log(client, fresh):
    fresh.post("/api/torque", json={"enabled": True})
    run_id = ok_json(fresh.post("/api/tests/sinusoid", json={"duration_s": 20}))["run_id"]
    wait_for(lambda: ok_json(fresh.get("/api/status"))["mode"] == "test", "the run to start")
    wait_for(lambda: fresh.get(f"/api/runs/{run_id}/log.csv").text.count("\n") > 50, "samples")

    def listed() -> dict:
        return next(r for r in ok_json(fresh.get("/api/runs")) if r["run_id"] == run_id)

    wait_for(lambda: listed()["samples"] > 50, "the live sample count in the run list")
    assert listed()["state"] == "running"
    saved = json.loads((client.app.state.runs.get(run_id).folder / "run.json").read_text())
    assert saved["state"] == "running"  # the record is on disk from the start
    assert fresh.post(f"/api/runs/{run_id}/abort").status_code == 200
    wait_for(
        lambda: _state(fresh, run_id) == "aborted",
        "the run to be marked aborted",
        seen=lambda: _run(fresh, run_id),
    )
    run = ok_json(fresh.get(f"/api/runs/{run_id}"))
    assert "operator" in run["reason"] and run["samples"] > 50
    folder = client.app.state.runs.get(run_id).folder
    assert len(read_messages(folder / "log.mcap")) == run["samples"]
    assert ok_json(fresh.get("/api/status"))["mode"] == "idle"


@pytest.mark.slow  # an end-to-end run of seconds
def test_estop_during_a_run_aborts_it(fresh):
    fresh.post("/api/torque", json={"enabled": True})
    run_id = ok_json(fresh.post("/api/tests/sinusoid", json={"duration_s": 20}))["run_id"]
    wait_for(lambda: ok_json(fresh.get("/api/status"))["mode"] == "test", "the run to start")
    fresh.post("/api/estop")
    wait_for(
        lambda: _state(fresh, run_id) == "aborted",
        "the run to be marked aborted",
        seen=lambda: _run(fresh, run_id),
    )
    assert ok_json(fresh.get(f"/api/runs/{run_id}"))["reason"] == "e-stop"
    assert fresh.get("/api/runs/nope").status_code == 404
    assert fresh.get(f"/api/runs/{run_id}/secrets.txt").status_code == 404


@pytest.mark.slow  # an end-to-end run of seconds
def test_waypoints_run_and_windowed_stats(fresh):
    fresh.post("/api/torque", json={"enabled": True})
    body = {
        "points_m": [[0, 0, -0.22], [0.03, 0, -0.22], [0.03, 0.03, -0.24]],
        "times_s": [0, 0.5, 1.0],
    }
    run_id = ok_json(fresh.post("/api/tests/waypoints", json=body))["run_id"]
    wait_for(
        lambda: _state(fresh, run_id) != "running",
        "the waypoint run to end",
        seen=lambda: _run(fresh, run_id),
    )
    assert ok_json(fresh.get(f"/api/runs/{run_id}"))["kind"] == "waypoints"
    whole = ok_json(fresh.get(f"/api/runs/{run_id}/stats"))["tracking"]
    late = ok_json(fresh.get(f"/api/runs/{run_id}/stats?start_s=0.5"))["tracking"]
    assert 0 < late["samples"] < whole["samples"]
    bad = {"points_m": [[0, 0, -0.22], [0.03, 0, -0.22]], "times_s": [0, 0]}
    assert fresh.post("/api/tests/waypoints", json=bad).status_code == 422


def test_chirp_too_fast_for_the_joints_is_refused(fresh):
    fresh.post("/api/torque", json={"enabled": True})
    response = fresh.post("/api/tests/chirp", json={"amplitude_m": 0.08, "f1_hz": 8.0})
    assert response.status_code == 422, response.text
    assert "infeasible" in response.json()["detail"]


@pytest.mark.slow  # an end-to-end run of seconds
def test_step_response_run(fresh):
    ended: list[dict] = []
    for _ in range(3):  # a fault a loaded machine caused (a starved emulator) ends a run
        fresh.post("/api/reset")  # early: reset and run it again, as an operator would
        fresh.post("/api/torque", json={"enabled": True})
        response = fresh.post("/api/tests/step", json={"size_m": 0.004, "duration_s": 1.0})
        assert response.status_code == 200, response.text
        run_id = response.json()["run_id"]
        wait_for(
            lambda r=run_id: _state(fresh, r) != "running",
            "the step run to end",
            seen=lambda r=run_id: _run(fresh, r),
        )
        ended.append(_run(fresh, run_id))
        if ended[-1]["state"] == "done":
            break
    assert ended[-1]["state"] == "done", [(r["state"], r["reason"]) for r in ended]
    rows = list(csv.DictReader(io.StringIO(fresh.get(f"/api/runs/{run_id}/log.csv").text)))
    goal_z = [float(r["goal_z_m"]) for r in rows if r["phase"] == "timed"]
    assert max(goal_z) - min(goal_z) == pytest.approx(0.004, abs=1e-9)  # a true step
    measured_z = [float(r["measured_z_m"]) for r in rows if r["phase"] == "timed"]
    assert max(measured_z) - min(measured_z) > 0.003  # and the robot followed it
    big = fresh.post("/api/tests/step", json={"size_m": 0.05})
    assert big.status_code == 422, big.text
    assert "joint speed" in big.json()["detail"]


@pytest.mark.slow  # a run of seconds, aborted
def test_a_running_run_says_how_far_it_is_and_is_not_compared_yet(fresh):
    fresh.post("/api/torque", json={"enabled": True})
    earlier = [r["run_id"] for r in ok_json(fresh.get("/api/runs")) if r["state"] != "running"]
    response = fresh.post("/api/tests/sinusoid", json={"duration_s": 5.0})
    assert response.status_code == 200, response.text
    run_id = response.json()["run_id"]

    def into_the_test() -> dict | None:
        progress = _run(fresh, run_id)["progress"]
        return progress if progress and progress["test_elapsed_s"] > 0 else None

    progress = wait_for(into_the_test, "the run to be in its test part")
    assert progress["test_duration_s"] == 5.0 and progress["phase"] in ("timed", "stop")
    assert 0 < progress["test_elapsed_s"] <= 5.0
    assert progress["test_elapsed_s"] < progress["elapsed_s"] <= progress["duration_s"]
    later = wait_for(into_the_test, "a later progress")
    assert later["elapsed_s"] >= progress["elapsed_s"]  # run time only goes forward
    assert "5 s" in _run(fresh, run_id)["description"]
    if earlier:
        compared = fresh.get("/api/runs/compare", params={"ids": f"{earlier[0]},{run_id}"})
        assert compared.status_code == 409 and run_id in compared.json()["detail"]
    ok_json(fresh.post(f"/api/runs/{run_id}/abort"))
    wait_for(lambda: _state(fresh, run_id) != "running", "the run to end")
    assert _run(fresh, run_id)["progress"] is None

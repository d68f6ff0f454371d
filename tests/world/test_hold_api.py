"""Hold-in-world through the API: pose input, the hold mode, staleness, the hold test run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with make_client(tmp_path_factory.mktemp("runs")) as test_client:
        take_lease(test_client)
        yield test_client


def _pose(t: float, z: float = 1.5) -> dict:
    return {"t": t, "position": [0.0, 0.0, z], "quaternion": [1.0, 0.0, 0.0, 0.0]}


def test_pose_post_vets_samples(client):
    client.post("/api/reset")
    assert ok_json(client.post("/api/mav/pose", json=_pose(1.0)))["accepted"] is True
    assert ok_json(client.post("/api/mav/pose", json=_pose(0.5)))["accepted"] is False
    for bad in (
        {**_pose(2.0), "quaternion": [0, 0, 0, 0]},
        {**_pose(2.0), "t": None},
        {"position": [0, 0, 1]},
    ):
        assert client.post("/api/mav/pose", json=bad).status_code == 422
    status = ok_json(client.get("/api/mav/pose"))
    assert status["accepted"] >= 1 and status["dropped"] >= 1


def test_pose_websocket_stream(client):
    with client.websocket_connect("/api/mav/pose") as ws:
        ws.send_text(json.dumps(_pose(10.0)))
        ws.send_text(json.dumps({**_pose(10.01), "quaternion": [3, 0, 0, 0]}))
        assert "unit" in ws.receive_json()["error"]
    assert ok_json(client.get("/api/mav/pose"))["accepted"] >= 2


def test_a_platform_marker_pose_is_its_own_stream(client):
    drone = ok_json(client.get("/api/mav/pose"))["accepted"]
    marker = ok_json(client.get("/api/mav/pose?body=platform"))["accepted"]
    body = {**_pose(500.0, z=-0.3), "body": "platform"}
    answer = ok_json(client.post("/api/mav/pose", json=body))
    assert answer["accepted"] is True and answer["input"]["accepted"] == marker + 1
    # the drone's stream did not see it (its next sample, older, is still taken)
    assert ok_json(client.post("/api/mav/pose", json=_pose(200.0)))["input"]["accepted"] == (
        drone + 1
    )
    with client.websocket_connect("/api/mav/pose") as ws:
        ws.send_text(json.dumps({**body, "t": 500.01}))
        ws.send_text(json.dumps({**body, "body": "tool"}))
        assert "body" in ws.receive_json()["error"]
        ws.send_text("[1]")  # not an object: answered, the stream stays open
        assert "object" in ws.receive_json()["error"]
    wait_for(
        lambda: ok_json(client.get("/api/mav/pose?body=platform"))["accepted"] == marker + 2,
        "the streamed marker pose",
    )
    bad = client.post("/api/mav/pose", json={**body, "body": "tool"})
    assert bad.status_code == 422 and "body" in bad.text
    assert client.get("/api/mav/pose?body=tool").status_code == 422


@pytest.mark.slow
def test_hold_faults_when_the_pose_stream_is_lost(client):
    ok_json(client.post("/api/reset"))
    ok_json(client.post("/api/torque", json={"enabled": True}))
    ok_json(client.post("/api/mav/pose", json=_pose(100.0)))
    response = client.post("/api/hold", json={"position_m": [0.0, 0.0, 1.5 - 0.08 - 0.24]})
    assert response.status_code == 200, response.text
    wait_for(lambda: ok_json(client.get("/api/status"))["mode"] == "fault", "the lost-pose fault")
    reason = ok_json(client.get("/api/status"))["faults"][0]["reason"]
    assert "pose" in reason and "lost" in reason
    client.post("/api/reset")


def _hold_run(client, body: dict) -> dict:
    client.post("/api/reset")
    client.post("/api/torque", json={"enabled": True})
    client.post("/api/goal", json={"position_m": [0.0, 0.0, -0.24]})
    response = client.post("/api/tests/hold", json=body)
    assert response.status_code == 200, response.text
    run_id = response.json()["run_id"]
    wait_for(lambda: ok_json(client.get(f"/api/runs/{run_id}"))["state"] != "running", "the run")
    run = ok_json(client.get(f"/api/runs/{run_id}"))
    assert run["state"] == "done" and run["kind"] == "hold"
    return run["stats"]["world"]


@pytest.mark.slow  # an end-to-end run of seconds
def test_a_still_drone_gives_no_world_error(client):
    """No drift: the world goal maps to a fixed base point; what is left is quantization."""
    still = {"drift_m": 0, "tilt_deg": 0, "yaw_deg": 0, "gust_m": 0, "duration_s": 1.5}
    world = _hold_run(client, still)
    for axis in "xyz":
        assert world[axis]["rmse_m"] < 0.002
    assert world["outside_s"] == 0.0


@pytest.mark.slow  # an end-to-end run of seconds
def test_hold_test_run_under_drift_reports_world_stats(client):
    world = _hold_run(client, {"duration_s": 2.0, "latency_compensation": True, "seed": 3})
    for axis in "xyz":  # a sanity bound: the figure itself is measured by benchmarks/runs.py
        assert 0.0 < world[axis]["rmse_m"] < 0.1
        assert world[axis]["max_abs_m"] >= world[axis]["rmse_m"]
    assert client.post("/api/tests/hold", json={"duration_s": -1}).status_code == 422


@pytest.mark.slow  # an end-to-end run of seconds
def test_telemetry_carries_the_world_frame_during_a_hold(client):
    """The dashboard plots the world frame from telemetry while a hold run is on."""
    client.post("/api/reset")
    client.post("/api/torque", json={"enabled": True})
    body = {"duration_s": 3.0, "seed": 1}
    run_id = ok_json(client.post("/api/tests/hold", json=body))["run_id"]
    with client.websocket_connect("/api/telemetry?hz=50") as ws:
        for _ in range(200):
            message = ws.receive_json()
            if message["world"] is not None:
                break
    world = message["world"]
    assert world is not None
    np.testing.assert_allclose(
        world["error_m"], np.subtract(world["goal_m"], world["measured_m"]), atol=1e-12
    )
    wait_for(lambda: ok_json(client.get(f"/api/runs/{run_id}"))["state"] != "running", "run")


def test_every_bad_websocket_frame_gets_an_error_and_the_stream_goes_on(client):
    accepted = ok_json(client.get("/api/mav/pose"))["accepted"]
    huge = '{"t": ' + "9" * 400 + ', "position": [0, 0, 1.5], "quaternion": [1, 0, 0, 0]}'
    with client.websocket_connect("/api/mav/pose") as ws:
        for frame, reason in (
            (b'{"t": 1}', "binary"),
            (huge, "large"),
            ("[" * 30_000 + "]" * 30_000, "deep"),
            ("[1, 2]", "object"),
        ):
            if isinstance(frame, bytes):
                ws.send_bytes(frame)
            else:
                ws.send_text(frame)
            assert reason in ws.receive_json()["error"]
        ws.send_text(json.dumps(_pose(9000.0)))
        ws.send_text("not json")  # answered: the connection is still open after the good one
        assert "JSON" in ws.receive_json()["error"]
    assert ok_json(client.get("/api/mav/pose"))["accepted"] == accepted + 1


def test_a_bad_body_query_names_the_field_and_the_reason(client):
    response = client.get("/api/mav/pose?body=moon")
    assert response.status_code == 422
    detail = response.json()["detail"]
    assert detail.startswith("query.body: ") and "'drone' or 'platform'" in detail

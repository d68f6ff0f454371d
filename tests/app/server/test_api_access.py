"""Token, control lease and the telemetry WebSocket."""

from __future__ import annotations

import pytest
from starlette.websockets import WebSocketDisconnect

from app.cli.serve import check_exposure
from app.config import ConfigError, load_settings
from tests.support.app_client import make_client
from tests.support.wait import ok_json

TOKEN = "s3cret-token"


@pytest.fixture(scope="module")
def guarded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs")
    with make_client(folder, server={"host": "0.0.0.0", "token": TOKEN}) as client:
        yield client


def test_control_needs_the_token_status_does_not(guarded):
    assert guarded.get("/api/status").status_code == 200
    assert guarded.post("/api/estop").status_code == 401
    assert guarded.post("/api/torque", json={"enabled": False}).status_code == 401
    wrong = {"Authorization": "Bearer nope-nope-nope"}
    assert guarded.post("/api/reset", headers=wrong).status_code == 401
    right = {"Authorization": f"Bearer {TOKEN}"}
    assert guarded.post("/api/reset", headers=right).status_code == 200


def test_websocket_needs_the_token(guarded):
    with pytest.raises(WebSocketDisconnect), guarded.websocket_connect("/api/telemetry") as ws:
        ws.receive_json()
    with guarded.websocket_connect(f"/api/telemetry?token={TOKEN}") as ws:
        assert "mode" in ws.receive_json()


def test_binding_beyond_loopback_needs_a_token():
    with pytest.raises(ConfigError, match="token"):
        check_exposure(load_settings(server={"host": "0.0.0.0"}))
    check_exposure(load_settings(server={"host": "127.0.0.1"}))


def test_one_client_holds_control_until_taken_over(client):
    alice, bob = {"X-Client": "alice"}, {"X-Client": "bob"}
    assert client.post("/api/reset", headers=alice).status_code == 200
    refused = client.post("/api/reset", headers=bob)
    assert refused.status_code == 409, refused.text
    assert "alice" in refused.json()["detail"]
    assert client.post("/api/estop", headers=bob).status_code == 200  # anyone may stop
    assert client.post("/api/lease", json={"client": "bob"}).status_code == 409
    assert client.post("/api/lease", json={"client": "bob", "take_over": True}).status_code == 200
    assert ok_json(client.get("/api/lease"))["holder"] == "bob"
    assert client.post("/api/reset", headers=bob).status_code == 200
    client.post("/api/lease", json={"client": "anonymous", "take_over": True})


def test_telemetry_streams_the_loop_state(client):
    with client.websocket_connect("/api/telemetry?hz=100") as ws:
        first, second = ws.receive_json(), ws.receive_json()
    for key in (
        "t",
        "mode",
        "goal_m",
        "commanded_joints_rad",
        "measured_joints_rad",
        "measured_m",
        "error_m",
        "loop",
        "faults",
    ):
        assert key in first
    assert second["tick"] > first["tick"]

"""Token, control lease and the telemetry WebSocket."""

from __future__ import annotations

import pytest
from starlette.websockets import WebSocketDisconnect

from app.cli.serve import check_exposure
from app.config import ConfigError, load_settings
from tests.support.app_client import make_client
from tests.support.lease import take_lease

TOKEN = "s3cret-token"


@pytest.fixture(scope="module")
def guarded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs")
    with make_client(folder, server={"host": "0.0.0.0", "token": TOKEN}) as client:
        yield client


def test_control_needs_the_token(guarded):
    assert guarded.post("/api/torque", json={"enabled": False}).status_code == 401
    wrong = {"Authorization": "Bearer nope-nope-nope"}
    assert guarded.post("/api/reset", headers=wrong).status_code == 401
    right = take_lease(guarded, token=TOKEN, sticky=False)
    assert guarded.post("/api/reset", headers=right).status_code == 200


def test_websocket_needs_the_token(guarded):
    # closed with the policy code 1008 after the handshake (the page asks for the token on
    # that code; a refused handshake would show the browser only 1006)
    with (
        pytest.raises(WebSocketDisconnect) as refused,
        guarded.websocket_connect("/api/telemetry") as ws,
    ):
        ws.receive_json()
    assert refused.value.code == 1008 and "token" in refused.value.reason
    with guarded.websocket_connect(f"/api/telemetry?token={TOKEN}") as ws:
        assert "mode" in ws.receive_json()


def test_binding_beyond_loopback_needs_a_token():
    with pytest.raises(ConfigError, match="token"):
        check_exposure(load_settings(server={"host": "0.0.0.0"}))
    check_exposure(load_settings(server={"host": "127.0.0.1"}))


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

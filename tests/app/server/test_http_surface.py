"""The typed HTTP surface: responses match their models, OpenAPI lists what routes answer,
and an exception that is not the project's own is a logged 500, never an operator error."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import load_settings
from app.control.state import Fault, Snapshot
from app.server import create_app
from app.server.api import serialize
from app.server.api.deps import get_runs
from app.server.api.responses import StatusOut, TelemetryMessage
from app.server.errors import INTERNAL_ERROR
from tests.support.app_client import LocalClient

SERVER = Path(__file__).resolve().parents[3] / "app" / "server"


@pytest.fixture(scope="module")
def bare() -> TestClient:
    """The app without its lifespan: routes and schema only, no bus, no loop."""
    return LocalClient(create_app(load_settings()))


def test_status_and_telemetry_match_their_models_exactly(fresh):
    """A key added to or dropped from the JSON and not the model (or back) fails here."""
    fresh.post("/api/torque", json={"enabled": True})
    fresh.post("/api/jog", json={"delta_m": [0.0, 0.0, 0.002]})
    StatusOut.model_validate(fresh.get("/api/status").json())
    TelemetryMessage.model_validate(fresh.get("/api/telemetry").json())
    with fresh.websocket_connect("/api/telemetry") as ws:
        message = ws.receive_json()
    TelemetryMessage.model_validate(message)
    assert set(message) == set(TelemetryMessage.model_fields)


def test_the_models_forbid_keys_they_do_not_name(fresh):
    status = fresh.get("/api/status").json()
    with pytest.raises(ValueError, match="extra"):
        StatusOut.model_validate({**status, "surprise": 1})
    with pytest.raises(ValueError, match="extra"):
        StatusOut.model_validate({**status, "loop": {**status["loop"], "surprise": 1}})


def test_telemetry_in_hold_mode_has_the_world_frame():
    """The world branch of the message, from a snapshot as the hold mode publishes it."""
    extra = {"goal_world_m": [1.0, 2.0, 3.0], "measured_world_m": [1.0, 2.0, 2.5]}
    snap = Snapshot(tick=7, mode="hold-world", extra=extra)
    message = serialize.telemetry(snap)
    parsed = TelemetryMessage.model_validate(message)
    assert parsed.world is not None and parsed.world.error_m == [0.0, 0.0, 0.5]
    assert parsed.measured_m == [None, None, None]  # unknown is null, not NaN
    assert np.isnan(snap.point_measured_m).all()


def _telemetry(snap: Snapshot) -> TelemetryMessage:
    return TelemetryMessage.model_validate(serialize.telemetry(snap))


@pytest.mark.parametrize(
    "change",
    [
        {"torque": False},
        {"estopped": True},
        {"faults": (Fault("following", "following error 0.4 rad on joint 2"),)},
        {"goal_m": np.array([0.0, np.nan, -0.24])},
    ],
    ids=["torque off", "e-stop", "fault", "no goal"],
)
def test_telemetry_error_is_null_without_a_setpoint(change):
    """Commanded minus measured is shown only while the loop holds a setpoint: a relaxed
    arm falling away from its last command has no tracking error to plot."""
    held = dict(
        torque=True,
        goal_m=np.array([0.0, 0.0, -0.24]),
        point_commanded_m=np.array([0.0, 0.0, -0.24]),
        point_measured_m=np.array([0.001, -0.002, -0.2435]),
    )
    shown = _telemetry(Snapshot(**held)).error_m
    assert shown == pytest.approx([-0.001, 0.002, 0.0035])  # goal - measured, as held
    assert _telemetry(Snapshot(**{**held, **change})).error_m == [None, None, None]


@pytest.mark.slow
def test_openapi_has_response_schemas_and_error_responses(bare):
    doc = bare.get("/openapi.json").json()
    paths = doc["paths"]

    def ok_schema(path: str, method: str = "get") -> dict:
        return paths[path][method]["responses"]["200"]["content"]["application/json"]["schema"]

    assert ok_schema("/api/status") == {"$ref": "#/components/schemas/StatusOut"}
    assert ok_schema("/api/runs")["items"] == {"$ref": "#/components/schemas/RunOut"}
    assert ok_schema("/api/telemetry") == {"$ref": "#/components/schemas/TelemetryMessage"}
    for name in ("StatusOut", "RunOut", "TelemetryMessage", "ErrorBody"):
        assert doc["components"]["schemas"][name]["properties"], name
    goal = paths["/api/goal"]["post"]["responses"]
    for code in ("401", "409", "422", "503"):
        schema = goal[code]["content"]["application/json"]["schema"]
        assert schema == {"$ref": "#/components/schemas/ErrorBody"}, code
    assert "404" in paths["/api/runs/{run_id}"]["get"]["responses"]
    # FastAPI's default 422 body (a list of errors) is not what this server sends
    assert "HTTPValidationError" not in doc["components"]["schemas"]


def test_every_json_route_declares_its_response_model(bare):
    for path, operations in bare.get("/openapi.json").json()["paths"].items():
        for method, operation in operations.items():
            content = operation["responses"]["200"].get("content", {})
            if "application/json" in content:
                assert content["application/json"]["schema"], f"{method} {path}"


def test_an_unexpected_exception_is_a_logged_500_with_a_generic_body(caplog):
    """A RuntimeError or ValueError from the server's own code is a bug, not a 503 or 422."""

    def broken() -> None:
        raise RuntimeError("a bug, not the operator's doing")

    app = create_app(load_settings())
    app.dependency_overrides[get_runs] = broken
    with caplog.at_level(logging.ERROR, logger="app.server.errors"):
        response = LocalClient(app).get("/api/runs")
    assert response.status_code == 500
    assert response.json() == {"detail": INTERNAL_ERROR}
    assert "a bug, not" not in response.text
    logged = [r for r in caplog.records if r.exc_info and r.exc_info[0] is RuntimeError]
    assert logged and "GET /api/runs" in logged[0].getMessage()
    assert "Traceback" in caplog.text and "a bug, not the operator's doing" in caplog.text


def test_routes_read_app_state_only_through_dependencies():
    for path in (SERVER / "api").glob("*.py"):
        if path.name != "deps.py":
            assert not re.search(r"\.app\.state|app\.state\.", path.read_text()), path.name


def test_hold_in_world_without_a_point_is_a_422_not_a_bug(fresh):
    fresh.post("/api/torque", json={"enabled": True})
    response = fresh.post("/api/hold", json={"frame": "world"})
    assert response.status_code == 422, response.text
    assert response.json()["detail"] == "position_m: required with frame 'world'"

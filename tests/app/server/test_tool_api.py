"""The tool tip through the API: goals are tips, status gives tip, platform and phi.

With ``[tool] offset_m = [0, 0, -0.05]`` on the twin (a 5 cm tool pointing down), a goal
given as a tip brings the tip there: FK says so, and so does the twin's own measurement of
its platform (``external_m``, the twin's true body plus the offset). A goal whose platform
point would be above the ceiling is refused although the tip is a good platform goal, and
nothing moves. Without [tool], the tip is the platform centre.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import load_settings
from app.control.commands import CommandContext
from tests.support.app_client import make_client, torque_on, wait_at
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

OFFSET = np.array([0.0, 0.0, -0.05])
TIP = np.array([0.02, -0.01, -0.28])  # the platform at [0.02, -0.01, -0.23]


def _status(client: TestClient) -> dict:
    return ok_json(client.get("/api/status"))


@pytest.fixture(scope="module")
def tooled(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("runs")
    with make_client(folder, backend="sim", tool={"offset_m": OFFSET.tolist()}) as client:
        take_lease(client)
        torque_on(client)
        yield client


def _motion(client: TestClient) -> dict:
    status = _status(client)
    return {
        "mode": status["mode"],
        "torque": status["torque"],
        "goal_m": status["goal"]["position_m"],
        "commanded_m": status["ee"]["commanded_m"],
        "commanded_rad": status["joints"]["commanded_rad"],
    }


@pytest.mark.slow  # end to end on the twin
def test_a_goal_given_as_a_tip_brings_the_tip_there(tooled):
    response = tooled.post("/api/goal", json={"position_m": TIP.tolist()})
    assert response.status_code == 200, response.text
    # within 3 mm (the gravity offset takes most of the factory gains' sag)
    wait_at(tooled, TIP, "the tool tip at the goal", within_m=0.003)
    ee = _status(tooled)["ee"]
    tip, platform = np.array(ee["position_m"]), np.array(ee["platform_m"])
    np.testing.assert_allclose(tip - platform, OFFSET, atol=1e-12)
    assert ee["phi_rad"] == 0.0 and _status(tooled)["goal"]["position_m"] == TIP.tolist()
    # the jerk-limited move ends exactly at the goal (with the gravity offset on, the
    # measured tip is within 3 mm before the command's last micrometres are done)
    wait_for(
        lambda: np.allclose(_status(tooled)["ee"]["commanded_m"], TIP, rtol=0, atol=1e-9),
        "the commanded tip exactly at the goal",
        seen=lambda: _status(tooled)["ee"]["commanded_m"],
    )
    # the twin's own body, not the encoders: its platform is 5 cm above the goal
    assert np.linalg.norm(np.array(ee["external_m"]) - TIP) < 0.003
    wait_for(
        lambda: (
            np.linalg.norm(np.array(_status(tooled)["ee"]["platform_m"]) - (TIP - OFFSET)) < 0.003
        ),
        "the platform centre 5 cm above the tip",
    )


@pytest.mark.slow  # end to end on the twin
def test_a_tip_whose_platform_would_be_outside_is_refused_and_nothing_moves(tooled):
    tip = [0.0, 0.0, -0.09]  # a good platform goal; with the tool the platform is at -0.04
    plain = CommandContext.from_settings(load_settings()).gate
    plain.solve(plain.check_point(tip), plain.robot.ik(TIP - OFFSET).joints)
    ok_json(tooled.post("/api/goal", json={"position_m": TIP.tolist()}))
    wait_for(  # the jog done: what it commands stays put from now on
        lambda: np.allclose(_motion(tooled)["commanded_m"], TIP, rtol=0, atol=1e-9),
        "the jog at the goal",
    )
    before = _motion(tooled)
    for path in ("/api/goal", "/api/move"):
        response = tooled.post(path, json={"position_m": tip})
        assert response.status_code == 422, response.text
        detail = response.json()["detail"]
        assert "position_m" in detail and "platform centre would be at" in detail
        nearest = np.array(response.json()["nearest_m"])
        assert nearest[2] <= plain.z_max_m + OFFSET[2] + 1e-9  # a tip whose platform passes
    response = tooled.post("/api/goal", json={"position_m": TIP.tolist(), "phi_rad": 0.5})
    assert response.status_code == 422 and "phi_rad" in response.text, response.text
    response = tooled.post("/api/move", json={"position_m": TIP.tolist(), "phi_rad": 0.5})
    assert response.status_code == 422 and "phi_rad" in response.text, response.text
    after = _motion(tooled)
    assert after["goal_m"] == before["goal_m"] and after["mode"] == before["mode"]
    np.testing.assert_allclose(after["commanded_rad"], before["commanded_rad"], atol=1e-9)


def test_without_a_tool_the_status_is_as_before(fresh):
    """The module's shared app (emulated bus, no [tool]): the tip is the platform."""
    status = _status(fresh)
    ee = status["ee"]
    assert ee["position_m"] == ee["platform_m"] and None not in ee["position_m"]
    assert ee["phi_rad"] == 0.0
    with fresh.websocket_connect("/api/telemetry") as ws:
        message = ws.receive_json()
    assert message["ee"]["position_m"] == message["measured_m"] == message["ee"]["platform_m"]
    assert message["ee"]["phi_rad"] == 0.0


@pytest.mark.parametrize(
    "body",
    [
        '{"position_m": [0, 0, -0.24], "phi_rad": 0.2}',
        '{"position_m": [0, 0, -0.24], "phi_rad": NaN}',
        '{"position_m": [0, 0, -0.24], "phi_rad": "0"}',
    ],
)
def test_phi_rad_without_a_wrist_is_422_naming_it(fresh, body):
    torque_on(fresh)
    before = _motion(fresh)
    for path in ("/api/goal", "/api/move"):
        response = fresh.post(path, content=body, headers={"content-type": "application/json"})
        assert response.status_code == 422, response.text
        assert "phi_rad" in response.text
    assert _motion(fresh) == before
    ok_json(fresh.post("/api/goal", json={"position_m": [0.0, 0.0, -0.24], "phi_rad": 0.0}))

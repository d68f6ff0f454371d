"""A tool offset to the side of a wrist: a tip goal with a heading turns the wrist and
puts the tip there (the tool and the wrist, built apart, together on the twin)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

OFFSET = np.array([0.03, 0.0, -0.05])  # 3 cm to the side: the heading moves the tip
TIP = np.array([0.01, 0.02, -0.28])
PHI = 0.6


def _ee(client: TestClient) -> dict:
    return ok_json(client.get("/api/status"))["ee"]


def _rz(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def client(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("runs")
    tool = {"offset_m": OFFSET.tolist()}
    with make_client(folder, backend="sim", tool=tool, wrist={"enabled": True}) as app:
        take_lease(app)
        torque_on(app)
        yield app


@pytest.mark.slow  # end to end on the twin
def test_a_tip_goal_with_a_heading_turns_the_wrist_and_puts_the_tip_there(client):
    ok_json(client.post("/api/goal", json={"position_m": TIP.tolist(), "phi_rad": PHI}))

    def there() -> bool:
        ee = _ee(client)
        return abs(ee["phi_rad"] - PHI) < 0.01 and np.linalg.norm(ee["position_m"] - TIP) < 0.003

    wait_for(
        there,
        "the wrist at 0.6 rad and the tip at the goal",
        timeout_s=60,
        seen=lambda: _ee(client),
    )
    ee = _ee(client)
    tip, platform = np.array(ee["position_m"]), np.array(ee["platform_m"])
    # the tip is the platform plus the offset turned by the wrist's own (measured) angle
    np.testing.assert_allclose(tip - platform, _rz(ee["phi_rad"]) @ OFFSET, atol=1e-9)
    # the platform is not where it would be without the turn: the heading mattered
    assert np.linalg.norm(platform - (TIP - OFFSET)) > 0.01
    # the twin's own body, not the encoders, carries the tip there
    assert np.linalg.norm(np.array(ee["external_m"]) - TIP) < 0.004


def test_a_heading_beyond_the_wrist_limits_is_refused_naming_phi_rad(client):
    goal = ok_json(client.get("/api/status"))["goal"]  # the setpoint, not the moving command
    response = client.post("/api/goal", json={"position_m": TIP.tolist(), "phi_rad": 3.5})
    assert response.status_code == 422, response.text
    assert "phi_rad" in response.text
    assert ok_json(client.get("/api/status"))["goal"] == goal

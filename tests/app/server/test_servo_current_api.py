"""PUT /api/servos/current: the legs' operating mode and Goal Current, on the emulated
servos (their registers computed by hand: 2.69 mA per unit), with torque off only."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from hardware.dynamixel.control_table import Reg
from tests.support.app_client import torque_on
from tests.support.servo_emulator import IDS
from tests.support.wait import ok_json

URL = "/api/servos/current"


def tables(client: TestClient) -> list:
    emulator = client.app.state.backend.emulator
    return [emulator.servo(i).table for i in IDS]


def registers(client: TestClient) -> list[tuple[int, int]]:
    return [(t.get(Reg.OPERATING_MODE), t.get(Reg.GOAL_CURRENT)) for t in tables(client)]


def test_with_torque_off_the_mode_and_goal_current_reach_the_servos(fresh: TestClient) -> None:
    body = {"operating_mode": "current_based_position", "goal_current_a": [0.5, 1.0, 0.25]}
    answer = fresh.put(URL, json=body)
    assert answer.status_code == 200, answer.text
    assert answer.json() == {
        "operating_mode": "current_based_position",
        "goal_current_a": pytest.approx([0.5, 1.0, 0.25]),
    }
    # 0.5 / 2.69 mA = 185.87 -> 186; 1.0 -> 371.75 -> 372; 0.25 -> 92.94 -> 93
    assert registers(fresh) == [(5, 186), (5, 372), (5, 93)]
    status = ok_json(fresh.get("/api/status"))
    assert status["servo_mode"] == "current_based_position"
    assert status["goal_current_a"] == pytest.approx([0.5, 1.0, 0.25])
    back = {"operating_mode": "position", "goal_current_a": [3.209] * 3}
    assert fresh.put(URL, json=back).status_code == 200
    assert registers(fresh) == [(3, 1193)] * 3  # 3.209 / 2.69 mA = 1192.94 -> 1193
    assert ok_json(fresh.get("/api/status"))["servo_mode"] == "position"


def test_with_torque_on_it_is_a_409_saying_so_and_nothing_is_written(fresh: TestClient) -> None:
    before = registers(fresh)
    torque_on(fresh)
    body = {"operating_mode": "current_based_position", "goal_current_a": [0.5, 0.5, 0.5]}
    answer = fresh.put(URL, json=body)
    assert answer.status_code == 409, answer.text
    assert "torque off" in answer.json()["detail"], answer.text
    assert registers(fresh) == before
    assert ok_json(fresh.get("/api/status"))["servo_mode"] == "position"


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"operating_mode": "current", "goal_current_a": [0.5] * 3}, "operating_mode"),
        ({"operating_mode": "position", "goal_current_a": [0.5, 0.5, 3.3]}, "goal_current_a"),
        ({"operating_mode": "position", "goal_current_a": [0.5, 0.0, 0.5]}, "goal_current_a"),
        ({"operating_mode": "position", "goal_current_a": [0.5, 0.5]}, "goal_current_a"),
        ({"operating_mode": "position"}, "goal_current_a"),
    ],
)
def test_a_bad_value_is_a_422_naming_the_field(fresh: TestClient, body: dict, field: str) -> None:
    before = registers(fresh)
    answer = fresh.put(URL, json=body)
    assert answer.status_code == 422, answer.text
    assert answer.json()["detail"].startswith(f"{field}"), answer.text
    assert registers(fresh) == before


def test_it_needs_control(fresh: TestClient) -> None:
    body = {"operating_mode": "position", "goal_current_a": [1.0] * 3}
    answer = fresh.put(URL, json=body, headers={"X-Lease": "not-the-lease"})
    assert answer.status_code in (401, 409), answer.text

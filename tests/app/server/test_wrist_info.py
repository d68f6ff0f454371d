"""What the page reads about the tool and the wrist: /api/info's ``tool_offset_m`` and
``wrist``, status ``goal.phi_rad`` and telemetry ``ee.goal_phi_rad`` (null without a wrist)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

OFFSET = [0.01, 0.0, -0.04]
WRIST = {"enabled": True, "min_angle_rad": -1.5, "max_angle_rad": 1.2}
TIP = [0.0, 0.0, -0.27]


@pytest.fixture(scope="module")
def wristed(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("runs")
    with make_client(folder, backend="sim", tool={"offset_m": OFFSET}, wrist=WRIST) as client:
        take_lease(client)
        torque_on(client)
        yield client


@pytest.mark.slow
def test_info_gives_the_tool_offset_and_the_wrist_s_limits(wristed: TestClient) -> None:
    info = ok_json(wristed.get("/api/info"))
    assert info["tool_offset_m"] == OFFSET
    assert info["wrist"] == {"enabled": True, "min_rad": -1.5, "max_rad": 1.2}


@pytest.mark.slow  # end to end on the twin
def test_a_goal_s_phi_is_the_status_goal_and_the_wrist_turns_to_it(wristed: TestClient) -> None:
    ok_json(wristed.post("/api/goal", json={"position_m": TIP, "phi_rad": 0.5}))
    status = ok_json(wristed.get("/api/status"))
    assert status["goal"]["phi_rad"] == pytest.approx(0.5)
    wait_for(
        lambda: abs(ok_json(wristed.get("/api/status"))["ee"]["phi_rad"] - 0.5) < 0.01,
        "the wrist at the goal's phi",
    )
    with wristed.websocket_connect("/api/telemetry?hz=50") as ws:
        message = ws.receive_json()
    assert message["ee"]["goal_phi_rad"] == pytest.approx(0.5)
    assert message["ee"]["phi_rad"] == pytest.approx(0.5, abs=0.01)


@pytest.mark.slow
def test_without_a_wrist_info_and_status_say_none(tmp_path) -> None:
    with make_client(tmp_path, backend="emulated") as client:
        info = ok_json(client.get("/api/info"))
        assert info["wrist"] == {"enabled": False, "min_rad": None, "max_rad": None}
        assert info["tool_offset_m"] == [0.0, 0.0, 0.0]
        take_lease(client)
        torque_on(client)
        wait_for(
            lambda: ok_json(client.get("/api/status"))["goal"]["position_m"][0] is not None,
            "a goal held after torque on",
        )
        assert ok_json(client.get("/api/status"))["goal"]["phi_rad"] is None

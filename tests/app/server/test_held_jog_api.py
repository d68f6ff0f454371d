"""Hold-to-move through the API on the MuJoCo twin: the killed client.

A client holds a jog (``POST /api/jog {"velocity_m_s": ...}`` every 50 ms), then stops
sending, as a frozen tab or a lost link would. The law: the commanded point stops
changing by itself. The time from the last heartbeat to the stop is printed, not asserted
(benchmarks/jog_deadman.py measures it; the figure is in docs/performance.md).
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

VELOCITY_M_S = [0.03, 0.0, 0.0]


@pytest.fixture(scope="module")
def client(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(tmp_path_factory.mktemp("runs"), backend="sim") as test_client:
        take_lease(test_client)
        yield test_client


def status(client: TestClient) -> dict:
    return ok_json(client.get("/api/status"))


def at_rest(client: TestClient, point_m: list[float]) -> None:
    """Torque on, a goal, and wait until the commanded point is there."""
    ok_json(client.post("/api/reset"))
    torque_on(client)  # waits while the relaxed arm still swings past its joint limits
    ok_json(client.post("/api/goal", json={"position_m": point_m}))
    wait_for(
        lambda: np.allclose(status(client)["ee"]["commanded_m"], point_m, atol=1e-6),
        "the commanded point at the start",
    )


def wait_still(client: TestClient, quiet_s: float = 0.3) -> tuple[float, np.ndarray]:
    """Poll status until the commanded point has not changed for ``quiet_s`` of loop time;
    (the loop time it was first seen at its final value [s], that point [m])."""
    seen: list[tuple[float, np.ndarray]] = []

    def still() -> bool:
        snap = status(client)
        seen.append((snap["time_s"], np.array(snap["ee"]["commanded_m"])))
        recent = np.array([p for t, p in seen if t >= seen[-1][0] - quiet_s])
        return seen[-1][0] - seen[0][0] > quiet_s and np.ptp(recent, axis=0).max() < 1e-9

    wait_for(still, "the commanded point to stop changing", seen=lambda: seen[-1])
    final = seen[-1][1]
    return next(t for t, p in seen if np.array_equal(p, final)), final


@pytest.mark.slow  # end to end on the twin
def test_a_held_jog_stops_by_itself_when_the_client_stops_sending(client) -> None:
    at_rest(client, [0.0, 0.0, -0.24])
    start = np.array(status(client)["ee"]["commanded_m"])
    last = {}
    for _ in range(10):  # held for ~0.5 s: a heartbeat every 50 ms
        last = ok_json(client.post("/api/jog", json={"velocity_m_s": VELOCITY_M_S}))["result"]
        time.sleep(0.05)  # the client's own heartbeat period, not a wait for an effect
    assert last["hold_s"] == pytest.approx(client.app.state.settings.jog.hold_timeout_s)
    # the client is "killed": no more heartbeats
    stop_s, end = wait_still(client)
    print(
        f"held jog stopped within {1e3 * (stop_s - last['time_s']):.0f} ms of the last "
        "heartbeat (status polling resolution; see benchmarks/jog_deadman.py)"
    )
    assert end[0] - start[0] > 0.005  # it did move while held
    # along +x only: a wrong axis or sign is millimetres off; the joint step limit on a
    # late tick bends the commanded path by a micrometre or two
    assert np.abs(end[1:] - start[1:]).max() < 1e-5
    snap = status(client)
    assert snap["mode"] == "jog" and "no heartbeat" in snap["notice"]
    assert snap["goal"]["position_m"] == pytest.approx(list(end), abs=1e-9)


@pytest.mark.slow  # end to end on the twin
def test_a_zero_velocity_stops_at_once_and_a_step_still_works(client) -> None:
    at_rest(client, [0.0, 0.0, -0.24])
    ok_json(client.post("/api/jog", json={"velocity_m_s": VELOCITY_M_S}))
    ok_json(client.post("/api/jog", json={"velocity_m_s": [0.0, 0.0, 0.0]}))
    _, stopped = wait_still(client)
    assert stopped[0] < 0.0 + 0.003  # braked near the start, not a hold timeout later
    assert "no heartbeat" not in (status(client)["notice"] or "")
    ok_json(client.post("/api/jog", json={"delta_m": [0.0, 0.0, 0.005]}))  # scripts' step
    _, stepped = wait_still(client)
    np.testing.assert_allclose(stepped, stopped + [0.0, 0.0, 0.005], atol=1e-6)


@pytest.mark.parametrize(
    "body",
    [
        "{}",
        '{"delta_m": [0.01, 0, 0], "velocity_m_s": [0.01, 0, 0]}',
        '{"velocity_m_s": [NaN, 0, 0]}',
        '{"velocity_m_s": [0.01, 0]}',
        '{"velocity_m_s": [0.01, 0, 0], "hold": true}',
    ],
)
def test_bad_jog_bodies_are_422_and_move_nothing(client, body: str) -> None:
    before = status(client)["goal"]["position_m"]
    headers = {"Content-Type": "application/json"}
    response = client.post("/api/jog", content=body, headers=headers)
    assert response.status_code == 422, response.text
    assert status(client)["goal"]["position_m"] == before

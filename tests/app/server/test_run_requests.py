"""Starting a run over HTTP: bounded, never blocking, and never for a caller that has gone.

Inputs that cannot run are a 422 naming the field (they were 500s), and no refused
request moves the robot.
"""

from __future__ import annotations

import json
import threading
from types import SimpleNamespace

import numpy as np
import pytest

from app.server.api import runs as runs_api
from tests.support.app_client import settle_at, ticks
from tests.support.wait import ok_json, wait_for

START_M = [0.0, 0.0, -0.24]
SHORT = {"duration_s": 0.5, "amplitude_m": [0.005, 0.005, 0.005]}


def commanded(client) -> list[float]:
    return ok_json(client.get("/api/status"))["ee"]["commanded_m"]


@pytest.fixture
def settled(fresh):
    settle_at(fresh, START_M)
    wait_for(lambda: setpoint_still(fresh), "the approach to end (the setpoint still)")
    return fresh


def setpoint_still(client) -> bool:
    """The commanded point is the same across loop ticks: from here a change is a motion."""
    first, tick = commanded(client), ticks(client)
    wait_for(lambda: ticks(client) > tick + 2, "loop ticks")
    return unmoved(first, commanded(client))


def unmoved(before, after) -> bool:
    """The same setpoint, to a nanometre (its last bits wobble as it is recomputed)."""
    return bool(np.allclose(before, after, rtol=0.0, atol=1e-9))


@pytest.mark.slow
@pytest.mark.parametrize(
    ("path", "body", "field"),
    [
        ("/api/tests/sinusoid", {"amplitude_m": [1e308, 0, 0]}, "amplitude_m.0"),
        ("/api/tests/chirp", {"f0_hz": 20.0, "f1_hz": 0.0}, "f1_hz"),
        ("/api/tests/step", {"step_at_s": 3.0, "duration_s": 2.0}, "step_at_s"),
        ("/api/tests/sinusoid", {"duration_s": "2"}, "duration_s"),
        ("/api/goal", {"position_m": ["0", "0", "-0.24"]}, "position_m.0"),
        ("/api/jog", {"delta_m": [0.001, 0, True]}, "delta_m.2"),
    ],
)
def test_input_that_cannot_run_is_a_422_naming_the_field(settled, path, body, field):
    before = commanded(settled)
    response = settled.post(path, json=body)
    assert response.status_code == 422, response.text
    assert field in response.json()["detail"]
    assert unmoved(before, commanded(settled))


@pytest.mark.slow  # end to end: plans and waits on the loop
def test_waypoints_too_fast_from_near_the_start_are_refused(settled):
    """5 cm in a microsecond, the robot within 1 mm of the first point."""
    before = commanded(settled)
    first = np.add(START_M, [0.0, 0.0, -0.0008]).tolist()
    body = {"points_m": [first, [0.05, 0.0, -0.2408]], "times_s": [0.0, 1e-6]}
    response = settled.post("/api/tests/waypoints", json=body)
    assert response.status_code == 422, response.text
    assert unmoved(before, commanded(settled))


class SlowPlanning:
    """Replaces RunManager.prepare: signals when planning began, waits for release."""

    def __init__(self, runs) -> None:
        self.real, self.began, self.release = runs.prepare, threading.Event(), threading.Event()

    def __call__(self, *args, **kwargs):
        self.began.set()
        assert self.release.wait(timeout=60), "the test never released the planner"
        return self.real(*args, **kwargs)


@pytest.fixture
def slow_planning(settled, monkeypatch):
    runs = settled.app.state.runs
    slow = SlowPlanning(runs)
    monkeypatch.setattr(runs, "prepare", slow)
    yield slow
    slow.release.set()


def _run_count(client) -> int:
    return len(ok_json(client.get("/api/runs")))


@pytest.mark.slow  # end to end: plans and waits on the loop
def test_planning_does_not_block_other_requests(settled, slow_planning):
    answers: list = []
    poster = threading.Thread(
        target=lambda: answers.append(settled.post("/api/tests/sinusoid", json=SHORT))
    )
    poster.start()
    try:
        assert slow_planning.began.wait(timeout=30), "planning never started"
        # planning is stuck, yet the status answers: the event loop is free
        assert ok_json(settled.get("/api/status"))["mode"] != "test"
        assert not answers
    finally:
        slow_planning.release.set()
        poster.join(timeout=60)
    assert answers and answers[0].status_code == 200, answers and answers[0].text
    run_id = answers[0].json()["run_id"]
    wait_for(
        lambda: ok_json(settled.get(f"/api/runs/{run_id}"))["state"] != "running", "the run to end"
    )


def _post_then_disconnect(client, path: str, body: dict) -> tuple[int, dict]:
    """POST through the app's ASGI interface from a client that hangs up once the body is
    sent: every later receive says http.disconnect. Returns the answer's status and JSON."""
    payload = json.dumps(body).encode()
    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": path,
        "raw_path": path.encode(),
        "query_string": b"",
        "root_path": "",
        "client": ("test", 1),
        "server": ("testserver", 80),
        "headers": [
            (b"host", b"127.0.0.1"),
            (b"content-type", b"application/json"),
            (b"content-length", str(len(payload)).encode()),
            (b"x-lease", client.headers["x-lease"].encode()),
        ],
    }
    messages = [{"type": "http.request", "body": payload, "more_body": False}]
    sent: list[dict] = []

    async def receive() -> dict:
        return messages.pop(0) if messages else {"type": "http.disconnect"}

    async def send(message: dict) -> None:
        sent.append(message)

    async def call() -> None:
        await client.app(scope, receive, send)

    client.portal.call(call)
    start = next(m for m in sent if m["type"] == "http.response.start")
    content = b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")
    return start["status"], json.loads(content)


def test_a_run_is_not_started_for_a_client_that_has_gone(settled):
    before, runs_before = commanded(settled), _run_count(settled)
    status_code, answer = _post_then_disconnect(settled, "/api/tests/sinusoid", SHORT)
    assert status_code == 409 and "disconnected" in answer["detail"], answer
    assert _run_count(settled) == runs_before
    status = ok_json(settled.get("/api/status"))
    assert status["mode"] != "test" and unmoved(before, status["ee"]["commanded_m"])


def test_a_run_planned_past_its_deadline_is_not_started(settled, monkeypatch):
    limit_s = settled.app.state.settings.runs.plan_timeout_s
    clock = iter([0.0, limit_s + 1.0])  # planning "took" longer than the bound
    monkeypatch.setattr(runs_api, "time", SimpleNamespace(monotonic=lambda: next(clock)))
    before, runs_before = commanded(settled), _run_count(settled)
    response = settled.post("/api/tests/sinusoid", json=SHORT)
    assert response.status_code == 503, response.text
    assert "runs.plan_timeout_s" in response.json()["detail"]
    assert _run_count(settled) == runs_before and unmoved(before, commanded(settled))

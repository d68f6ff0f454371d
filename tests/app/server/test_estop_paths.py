"""The e-stop's early paths (app/server/estop.py): the outermost middleware latches a
POST /api/estop before routing, and the listener in its own thread (its port in /api/info)
e-stops on POST /estop and does nothing else. No timing is asserted: the figures are in
docs/dashboard.md (benchmarks/estop_latency.py)."""

from __future__ import annotations

import http.client
import json
import urllib.error
import urllib.request

import pytest

from tests.support.app_client import cleared
from tests.support.wait import ok_json, wait_for


def listener_url(client, path: str = "/estop") -> str:
    port = ok_json(client.get("/api/info"))["estop_port"]
    assert isinstance(port, int) and port > 0
    return f"http://127.0.0.1:{port}{path}"


def call(url: str, method: str = "POST", headers: dict | None = None) -> tuple[int, dict, bytes]:
    """(status, headers, body) of one request, errors included."""
    request = urllib.request.Request(url, method=method, headers=headers or {})
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return response.status, dict(response.headers), response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, dict(exc.headers), exc.read()


def status(client) -> dict:
    return ok_json(client.get("/api/status"))


@pytest.mark.slow
def test_a_post_to_the_listener_estops_the_controller(fresh):
    assert not status(fresh)["estopped"]
    code, _, body = call(listener_url(fresh) + "?press=listener-1")
    assert code == 200, body
    assert "result" in json.loads(body)
    after = wait_for(lambda: (s := status(fresh))["estopped"] and s, "the listener's e-stop")
    assert set(after["estop_arrivals_unix_s"]) == {"listener"}
    assert after["estop_received_unix_s"] == after["estop_arrivals_unix_s"]["listener"]
    # and it holds: a move is refused until Reset
    assert fresh.post("/api/torque", json={"enabled": True}).status_code == 409


@pytest.mark.slow
def test_the_listener_does_nothing_but_stop(fresh):
    """Other paths, other methods, a reset or a goal through it: refused, nothing happens."""
    before = status(fresh)
    for path, method in [
        ("/api/reset", "POST"),
        ("/api/goal", "POST"),
        ("/api/torque", "POST"),
        ("/", "POST"),
        ("/estop/../api/reset", "POST"),
        ("/estop", "GET"),
        ("/estop", "PUT"),
        ("/estop", "DELETE"),
        ("/ready", "GET"),  # the page's warm connection: 204, nothing done
    ]:
        code, _, _ = call(listener_url(fresh, path), method)
        assert code in ((204,) if path == "/ready" else (404, 501)), (path, method, code)
    after = status(fresh)
    assert not after["estopped"]
    assert after["estop_received_unix_s"] == before["estop_received_unix_s"]


def test_only_the_pages_origin_may_read_the_listeners_answer(fresh):
    page = f"http://localhost:{fresh.app.state.settings.server.http_port}"
    _, headers, _ = call(listener_url(fresh), headers={"Origin": page})
    assert headers.get("Access-Control-Allow-Origin") == page
    cleared(fresh)
    _, headers, _ = call(listener_url(fresh), headers={"Origin": "http://evil.example"})
    assert "Access-Control-Allow-Origin" not in headers  # it still stops: anyone may stop
    assert wait_for(lambda: status(fresh)["estopped"], "the e-stop")


def test_api_estop_is_latched_by_the_middleware_before_the_route(fresh):
    response = fresh.post("/api/estop", params={"press": "api-1"})
    assert response.status_code == 200, response.text
    after = status(fresh)
    assert after["estopped"]
    arrivals = after["estop_arrivals_unix_s"]
    assert set(arrivals) == {"middleware", "route"}
    assert arrivals["middleware"] <= arrivals["route"]
    assert after["estop_received_unix_s"] == arrivals["middleware"]


def test_one_press_by_both_paths_counts_once_at_its_first_arrival(fresh):
    fresh.post("/api/estop", params={"press": "both-1"})
    first = status(fresh)
    code, _, _ = call(listener_url(fresh) + "?press=both-1")
    assert code == 200
    again = status(fresh)
    assert again["estop_received_unix_s"] == first["estop_received_unix_s"]
    assert set(again["estop_arrivals_unix_s"]) == {"middleware", "route", "listener"}
    # a new press (another id, or none) is a new arrival
    cleared(fresh)
    call(listener_url(fresh) + "?press=both-2")
    assert status(fresh)["estop_received_unix_s"] > first["estop_received_unix_s"]


@pytest.mark.parametrize("press", ["", "x" * 65, "a b", "../x", "é"])
def test_a_bad_press_id_still_stops(fresh, press):
    response = fresh.post("/api/estop", params={"press": press})
    assert response.status_code == 200, response.text
    assert status(fresh)["estopped"]


def test_one_kept_alive_connection_serves_presses_and_a_large_body_is_not_read(fresh):
    port = ok_json(fresh.get("/api/info"))["estop_port"]
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        connection.request("GET", "/ready")
        ready = connection.getresponse()
        assert ready.status == 204
        ready.read()
        connection.request("POST", "/estop?press=kept-1", body=b"x" * 100)
        response = connection.getresponse()
        assert response.status == 200 and "result" in json.loads(response.read())
        assert status(fresh)["estopped"]
        cleared(fresh)
        connection.request("POST", "/estop?press=kept-2", body=b"x" * 100_000)
        response = connection.getresponse()
        assert response.status == 200  # it stops whatever the body; the body is not read
        assert response.getheader("Connection", "").lower() == "close"
        response.read()
    finally:
        connection.close()
    assert wait_for(lambda: status(fresh)["estopped"], "the e-stop with a large body")


@pytest.mark.slow  # connections held past the listener's header timeout (wall time)
def test_connections_held_open_or_trickling_cannot_lock_a_press_out(fresh):
    """A slowloris: every one of the listener's connections held by a client that sends
    nothing, or a header one byte at a time. A new press still gets in (the longest-waiting
    connection is closed for it) and stops the robot."""
    import socket

    from app.robot.estop import MAX_CONNECTIONS

    port = ok_json(fresh.get("/api/info"))["estop_port"]
    held = []
    try:
        for k in range(MAX_CONNECTIONS + 4):
            s = socket.create_connection(("127.0.0.1", port), timeout=10)
            if k % 2:
                s.sendall(b"POST /est")  # a header begun, never finished
            held.append(s)
        code, _, body = call(f"http://127.0.0.1:{port}/estop?press=through-the-crowd")
        assert code == 200, body
        assert wait_for(lambda: status(fresh)["estopped"], "the press through a full listener")
    finally:
        for s in held:
            s.close()

"""Issue 28 point 1: other web origins. With the default install (loopback, no token) a
DNS-rebinding page (``Host: rebind.evil.example:PORT``) took the lease, reset, turned
torque on and moved the tool 40 mm, and a page of another origin fed poses and read
telemetry. The Host and Origin checks (app/origins.py) refuse both; curl and the server's
own pages pass."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from app.origins import OriginPolicy, split_host
from tests.support.app_client import make_client, unmoved
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

REBIND = {"Host": "rebind.evil.example:8000", "Origin": "http://rebind.evil.example:8000"}
OTHER_SITE = {"Origin": "http://evil.example"}


@pytest.mark.parametrize(
    ("header", "parsed"),
    [
        ("127.0.0.1:8000", ("127.0.0.1", 8000)),
        ("LocalHost.", ("localhost", None)),
        ("[::1]:8080", ("::1", 8080)),
        ("::1", ("::1", None)),
        ("example.org:0", None),
        ("example.org:99999", None),
        ("example.org:80a", None),
        ("[::1", None),
        ("", None),
    ],
)
def test_host_headers_split_into_name_and_port(header, parsed):
    assert split_host(header) == parsed


@pytest.mark.parametrize(
    ("host", "origin", "refused"),
    [
        ("127.0.0.1:8000", None, False),  # curl
        ("127.0.0.1:8000", "http://127.0.0.1:8000", False),  # the page itself
        ("localhost:8080", "http://localhost:8080", False),  # the scene in its frame
        ("[::1]:8000", "http://[::1]:8000", False),
        ("10.0.0.7:8000", "http://10.0.0.7:8000", False),  # an address: no rebinding
        ("robot.localhost:8000", None, False),  # resolved to loopback by the browser
        ("localhost", "http://localhost:80", False),  # the default port either way
        ("rebind.evil.example:8000", "http://rebind.evil.example:8000", True),
        ("rebind.evil.example:8000", None, True),
        ("127.0.0.1:8000", "http://evil.example", True),
        ("127.0.0.1:8000", "http://127.0.0.1:8001", True),  # another local service
        ("127.0.0.1:8000", "https://127.0.0.1:8000", False),  # behind a TLS proxy
        ("127.0.0.1:8000", "null", True),  # a sandboxed frame or a file
        ("127.0.0.1:8000", "http://127.0.0.1:8000/path", True),
        (None, None, True),
    ],
)
def test_the_policy_passes_this_machine_and_its_own_origin_only(host, origin, refused):
    reason = OriginPolicy().refusal(host, origin)
    assert (reason is not None) == refused, reason


def test_configured_hosts_and_origins_pass_and_name_the_setting():
    policy = OriginPolicy(("robot.lab",), ("http://ground.lab:3000",))
    assert policy.refusal("robot.lab:8000", "http://robot.lab:8000") is None
    assert policy.refusal("robot.lab:8000", "http://ground.lab:3000") is None
    assert "allowed_hosts" in (policy.refusal("other.lab:8000", None) or "")
    assert "allowed_origins" in (policy.refusal("robot.lab:8000", "http://x.lab") or "")
    assert OriginPolicy(("*",)).refusal("anything.example", None) is None
    assert policy.refusal_of_headers([(b"host", b"robot.lab"), (b"host", b"evil")]) is not None


def test_the_bind_name_is_accepted():
    class Server:
        host, allowed_hosts, allowed_origins = "delta-bench", (), ()

    assert OriginPolicy.from_settings(Server()).refusal("delta-bench:8000", None) is None


GOAL = [0.0, 0.01, -0.23]


@pytest.fixture(scope="module")
def client(tmp_path_factory) -> Iterator[TestClient]:
    """The default install (no token), the robot holding GOAL, control free for anyone."""
    with make_client(tmp_path_factory.mktemp("runs")) as client:
        headers = take_lease(client, sticky=False)
        ok_json(client.post("/api/reset", headers=headers))
        ok_json(client.post("/api/torque", json={"enabled": True}, headers=headers))
        ok_json(client.post("/api/goal", json={"position_m": GOAL}, headers=headers))
        wait_for(  # to unmoved's 1 nm: the approach's last micrometre is still a motion
            lambda: np.allclose(robot(client)["commanded_m"], GOAL, rtol=0, atol=1e-10),
            "the approach to the goal done",
        )
        ok_json(client.delete("/api/lease", headers=headers))
        yield client


def robot(client: TestClient) -> dict:
    status = ok_json(client.get("/api/status"))
    return {
        "goal_m": status["goal"]["position_m"],
        "commanded_m": status["ee"]["commanded_m"],
        "torque": status["torque"],
        "mode": status["mode"],
    }


@pytest.mark.slow
@pytest.mark.parametrize("headers", [REBIND, OTHER_SITE], ids=["rebinding", "other-site"])
def test_another_sites_page_cannot_take_control_move_or_read(client, headers):
    before = robot(client)
    attempts = [
        ("post", "/api/lease", {"client": "evil", "take_over": True}),
        ("post", "/api/reset", None),
        ("post", "/api/torque", {"enabled": True}),
        ("post", "/api/goal", {"position_m": [0.0, 0.0, -0.2]}),
        ("post", "/api/mav/pose", {"t": 0.0, "position_m": [0, 0, 1], "quaternion": [1, 0, 0, 0]}),
        ("get", "/api/status", None),
        ("get", "/api/mav/pose", None),
    ]
    for method, path, body in attempts:
        response = client.request(method.upper(), path, json=body, headers=headers)
        assert response.status_code == 403, (path, response.status_code, response.text)
        detail = response.json()["detail"]
        assert ("Host" in detail) if "Host" in headers else ("Origin" in detail), detail
    assert not ok_json(client.get("/api/lease"))["held"]
    assert unmoved(before, robot(client)), (before, robot(client))
    with (
        pytest.raises(WebSocketDisconnect) as closed,
        client.websocket_connect("/api/telemetry", headers=headers) as ws,
    ):
        ws.receive_json()
    assert closed.value.code == 1008


def test_curl_and_the_servers_own_page_still_work(client):
    assert client.get("/api/status", headers={"Host": "127.0.0.1:8000"}).status_code == 200
    own = {"Origin": "http://127.0.0.1"}  # the test client's own origin (port 80)
    assert client.get("/api/status", headers=own).status_code == 200
    with client.websocket_connect("/api/telemetry", headers=own) as ws:
        assert ws.receive_json()["tick"] >= 0


def test_an_e_stop_from_anywhere_still_stops(client):
    """Stopping moves nothing and reads nothing: it is never refused."""
    response = client.post("/api/estop", headers=REBIND)
    assert response.status_code == 200, response.text
    assert robot(client)["mode"] == "estop"

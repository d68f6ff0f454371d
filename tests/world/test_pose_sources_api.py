"""The pose inputs' health through the API: a poison datagram, a dead listener, a reset."""

from __future__ import annotations

import json
import socket

import pytest

from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _datagram(t: float, **extra) -> bytes:
    pose = {"t": t, "position": [0.0, 0.0, 1.0], "quaternion": [1, 0, 0, 0], **extra}
    return json.dumps(pose).encode()


def _source(client, name: str) -> dict:
    sources = ok_json(client.get("/api/mav/pose"))["sources"]
    return next(source for source in sources if source["name"] == name)


@pytest.fixture(scope="module")
def udp(tmp_path_factory):
    port = _free_port()
    with make_client(tmp_path_factory.mktemp("runs"), world={"udp_port": port}) as client:
        take_lease(client)
        yield client, port


def test_a_poison_datagram_is_counted_named_and_the_input_goes_on(udp):
    client, port = udp
    before = ok_json(client.get("/api/mav/pose"))
    poison = b'{"t": ' + b"9" * 400 + b', "position": [0, 0, 1], "quaternion": [1, 0, 0, 0]}'
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        sender.sendto(poison, ("127.0.0.1", port))
        sender.sendto(b"[" * 30_000 + b"]" * 30_000, ("127.0.0.1", port))
        wait_for(
            lambda: ok_json(client.get("/api/mav/pose"))["udp_errors"] == before["udp_errors"] + 2,
            "both poison datagrams counted",
        )
        assert "deep" in _source(client, "udp")["last_error"]
        sender.sendto(_datagram(1000.0), ("127.0.0.1", port))
        wait_for(
            lambda: ok_json(client.get("/api/mav/pose"))["accepted"] == before["accepted"] + 1,
            "a good datagram accepted after the poison ones",
        )
    udp_source = _source(client, "udp")
    assert udp_source["alive"] is True and udp_source["rule"] == "open"


def test_a_dead_udp_input_shows_in_the_status_and_reset_restarts_it(udp):
    client, port = udp
    listener = next(x for x in client.app.state.node.world.service._listeners if x.name == "udp")
    listener.socket.close()  # the socket fails under the thread
    wait_for(lambda: _source(client, "udp")["alive"] is False, "the dead input in the status")
    assert "socket" in _source(client, "udp")["last_error"]
    assert client.post("/api/reset").status_code == 200
    restarted = _source(client, "udp")
    assert restarted["alive"] is True and restarted["restarts"] == 1
    accepted = ok_json(client.get("/api/mav/pose"))["accepted"]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        sender.sendto(_datagram(2000.0), ("127.0.0.1", port))
    wait_for(
        lambda: ok_json(client.get("/api/mav/pose"))["accepted"] == accepted + 1,
        "a datagram accepted after the reset",
    )


@pytest.mark.slow
def test_with_a_token_every_pose_source_needs_it_or_says_why_not(tmp_path):
    from starlette.websockets import WebSocketDisconnect

    token, port = "s3cret-token", _free_port()
    world = {"udp_port": port, "mavlink_url": f"udpin:127.0.0.1:{_free_port()}"}
    with make_client(tmp_path, server={"token": token}, world=world) as client:
        rules = {s["name"]: s["rule"] for s in ok_json(client.get("/api/mav/pose"))["sources"]}
        assert rules == {
            "http": "token",
            "websocket": "token",
            "udp": "token",
            "mavlink": "refused",
        }
        body = {"t": 1.0, "position": [0.0, 0.0, 1.0], "quaternion": [1.0, 0.0, 0.0, 0.0]}
        assert client.post("/api/mav/pose", json=body).status_code == 401
        with pytest.raises(WebSocketDisconnect), client.websocket_connect("/api/mav/pose") as ws:
            ws.receive_json()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.sendto(_datagram(5.0), ("127.0.0.1", port))
            wait_for(lambda: _source(client, "udp")["refused"] == 1, "the tokenless datagram")
            sender.sendto(_datagram(6.0, token=token), ("127.0.0.1", port))
            wait_for(lambda: _source(client, "udp")["accepted"] == 1, "the datagram with it")
        assert ok_json(client.get("/api/mav/pose"))["accepted"] == 1

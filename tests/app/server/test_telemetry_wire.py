"""The telemetry WebSocket as a browser meets it: a real ``deltadash serve`` (uvicorn) and a
real WebSocket client. Without the token the stream is closed with the policy code 1008
after the handshake (the page asks for the token on that code); a handshake refused instead
is an HTTP 403, of which a browser's close event says only 1006. With it, the stream flows."""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from tests.support.server import Server, serve

TOKEN = "wire-test-token"
pytestmark = pytest.mark.slow  # a server of its own


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[Server]:
    with serve(tmp_path_factory.mktemp("wire"), DELTADASH_SERVER__TOKEN=TOKEN) as served:
        yield served


def _ws(server: Server) -> str:
    return server.url.replace("http://", "ws://", 1) + "/api/telemetry"


def test_without_the_token_the_stream_closes_with_the_policy_code(server: Server) -> None:
    try:
        with connect(_ws(server), open_timeout=30) as ws, pytest.raises(ConnectionClosed) as closed:
            ws.recv(timeout=30)
    except InvalidStatus as refused:  # the handshake refused: what a browser shows as 1006
        pytest.fail(f"handshake refused with HTTP {refused.response.status_code}, not 1008")
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
    assert "token" in closed.value.rcvd.reason


def test_with_the_token_the_stream_flows(server: Server) -> None:
    with connect(f"{_ws(server)}?token={TOKEN}", open_timeout=30) as ws:
        assert "mode" in json.loads(ws.recv(timeout=30))

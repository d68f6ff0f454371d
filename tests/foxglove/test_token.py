"""With ``server.token`` set, the Foxglove live server takes only clients that send it
(``?token=`` or a Bearer header), as the API's WebSockets do; others get HTTP 401 before
any of the protocol. Beyond loopback without a token it does not start at all."""

from __future__ import annotations

import socket
from types import SimpleNamespace

import pytest
from websockets.exceptions import InvalidStatus

from app.config import ConfigError, load_settings
from app.control.state import Snapshot
from app.foxglove import messages
from app.foxglove.live import FoxgloveLive, bind_host
from tests.foxglove.client import SUBPROTOCOL, FoxgloveClient
from tests.support.app_client import make_client

TOKEN = "a-long-foxglove-secret"


@pytest.mark.slow  # an app of its own
def test_only_a_client_with_the_token_gets_in(tmp_path):
    with make_client(
        tmp_path, server={"token": TOKEN}, foxglove={"enabled": True, "port": 0}
    ) as app_client:
        live = app_client.app.state.foxglove
        url = f"ws://127.0.0.1:{live.port}"
        assert live.front is not None and live.port != live.server.port  # the door, then it
        refused = (
            (url, None),
            (f"{url}/?token=wrong-token-here", None),
            (url, {"Authorization": f"Token {TOKEN}"}),  # only Bearer, as the API
            (url, {"Authorization": "Bearer wrong-token-here"}),
        )
        for address, headers in refused:
            with pytest.raises(InvalidStatus) as caught:
                FoxgloveClient(address, headers)
            assert caught.value.response.status_code == 401, (address, headers)
            assert b"token" in caught.value.response.body
        assert live.front.refused == len(refused)
        for address, headers in (
            (f"{url}/?token={TOKEN}", None),
            (url, {"Authorization": f"Bearer {TOKEN}"}),
        ):
            with FoxgloveClient(address, headers) as fox:
                assert fox.ws.subprotocol == SUBPROTOCOL
                fox.subscribe({messages.LOOP, messages.TF})
                for topic in (messages.LOOP, messages.TF):
                    fox.wait_message(topic, lambda m: True, f"a message on {topic}")
                assert fox.server_info is not None and fox.server_info["name"] == "deltadash"
                loop = fox.messages(messages.LOOP)[-1].message
                assert loop["target_hz"] == app_client.app.state.settings.loop.rate_hz
                assert not fox.errors, fox.errors


def test_beyond_loopback_a_token_must_be_set():
    def settings(**server):
        return load_settings(foxglove={"enabled": True, "host": "0.0.0.0"}, server=server)

    with pytest.raises(ConfigError, match=r"foxglove.host = '0.0.0.0'.*server.token"):
        bind_host(settings())
    assert bind_host(settings(token=TOKEN)) == "0.0.0.0"
    # unset, it is the API's host, and its rule
    assert bind_host(load_settings(server={"host": "127.0.0.1"})) == "127.0.0.1"
    with pytest.raises(ConfigError):
        bind_host(load_settings(server={"host": "192.168.1.5"}))
    assert bind_host(load_settings(server={"host": "::1"})) == "::1"


@pytest.mark.parametrize("token", [None, TOKEN], ids=["sdk", "front"])
def test_a_taken_port_stops_it_naming_the_address(token):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        settings = load_settings(server={"token": token}, foxglove={"enabled": True, "port": port})
        live = FoxgloveLive(settings, SimpleNamespace(snapshot=Snapshot), lambda: None)
        with pytest.raises(RuntimeError, match=rf"Foxglove live server on 127.0.0.1:{port}: "):
            live.start()

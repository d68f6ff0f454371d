"""Issue 28 point 1 on the scene's port: from ``Origin: http://evil.example`` the scene
accepted a WebSocket client as unlocked (no token set) and it jogged 5 mm; a DNS-rebinding
page could load and drive it too. The port now refuses both before viser sees them."""

from __future__ import annotations

import base64
import os
import socket

import pytest
import viser

REBIND_HOST = "rebind.evil.example"


def handshake(port: int, host: str, origin: str | None, path: str = "/") -> int:
    """The HTTP status a WebSocket handshake to the scene's port gets (101: opened)."""
    key = base64.b64encode(os.urandom(16)).decode()
    lines = [
        f"GET {path} HTTP/1.1",
        f"Host: {host}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Key: {key}",
        "Sec-WebSocket-Version: 13",
        f"Sec-WebSocket-Protocol: viser-v{viser.__version__}",
    ]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    return _status(port, "\r\n".join(lines) + "\r\n\r\n")


def page(port: int, host: str) -> int:
    """The HTTP status of the scene's page fetched under ``Host: host``."""
    return _status(port, f"GET / HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n")


def _status(port: int, request: str) -> int:
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall(request.encode())
        head = b""
        while b"\r\n" not in head:
            chunk = sock.recv(4096)
            if not chunk:
                break
            head += chunk
    return int(head.split(b" ", 2)[1])


@pytest.mark.slow
@pytest.mark.parametrize(
    ("host", "origin"),
    [
        ("127.0.0.1:{port}", "http://evil.example"),  # another site's page
        (REBIND_HOST + ":{port}", "http://" + REBIND_HOST + ":{port}"),  # rebinding
        ("127.0.0.1:{port}", "http://127.0.0.1:1"),  # another local service
        ("127.0.0.1:{port}", "null"),
    ],
)
def test_another_sites_page_cannot_open_the_scene(scene, host, origin):
    port = scene.server.get_port()
    before = set(scene.server.get_clients())
    status = handshake(port, host.format(port=port), origin.format(port=port))
    assert status == 403
    assert set(scene.server.get_clients()) == before  # viser never saw it


def test_a_rebinding_page_cannot_load_the_scene(scene):
    port = scene.server.get_port()
    assert page(port, f"{REBIND_HOST}:{port}") == 403
    assert page(port, f"127.0.0.1:{port}") == 200


@pytest.mark.parametrize("name", ["127.0.0.1", "localhost"])
def test_the_scenes_own_page_still_opens_it(scene, name):
    """The dashboard embeds the scene from the other loopback name (static/js/isolation.js):
    its WebSocket's origin is the scene's own."""
    port = scene.server.get_port()
    assert handshake(port, f"{name}:{port}", f"http://{name}:{port}") == 101
    assert handshake(port, f"{name}:{port}", None) == 101  # a script, no Origin

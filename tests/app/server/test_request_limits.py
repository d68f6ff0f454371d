"""The door: a control request without the token, or with a body over the limit, is
refused before its body is read (the app never sees it, the client's receive is never
called), and a body within the limit reaches the app whole, disconnects included."""

from __future__ import annotations

import asyncio
import json

import pytest

from app.config import load_settings
from app.server.limits import RequestLimits
from tests.support.app_client import make_client

TOKEN = "s3cret-token"
LIMIT = 4096


def scope(path="/api/goal", method="POST", headers=()) -> dict:
    return {"type": "http", "method": method, "path": path, "headers": list(headers)}


class Client:
    """A client's side of ASGI: body chunks to hand out, and a count of how many were read."""

    def __init__(self, chunks: list[bytes]) -> None:
        self.chunks, self.read = list(chunks), 0

    async def receive(self) -> dict:
        if not self.chunks:
            return {"type": "http.disconnect"}
        self.read += 1
        chunk = self.chunks.pop(0)
        return {"type": "http.request", "body": chunk, "more_body": bool(self.chunks)}


class App:
    """The app behind the door: records that it was called and what body it read."""

    def __init__(self) -> None:
        self.called, self.body, self.after = False, b"", None

    async def __call__(self, scope, receive, send) -> None:
        self.called = True
        message = await receive()
        self.body = message["body"]
        self.after = (await receive())["type"]
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"{}"})


def through(request_scope: dict, client: Client, token: str | None = TOKEN):
    settings = load_settings(server={"token": token, "max_body_bytes": LIMIT})
    app, sent = App(), []

    async def send(message: dict) -> None:
        sent.append(message)

    asyncio.run(RequestLimits(app, settings)(request_scope, client.receive, send))
    status = next(m["status"] for m in sent if m["type"] == "http.response.start")
    body = b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")
    return status, json.loads(body), app


def auth(token: str) -> tuple[bytes, bytes]:
    return (b"authorization", f"Bearer {token}".encode())


def length(size: int) -> tuple[bytes, bytes]:
    return (b"content-length", str(size).encode())


HUGE = 16 << 20


@pytest.mark.parametrize("token", [None, "wrong-token", TOKEN])
def test_the_token_is_checked_before_the_body_is_read(token):
    headers = [length(HUGE)] + ([auth(token)] if token else [])
    client = Client([b"x" * 1024] * 3)
    status, answer, app = through(scope(headers=headers), client)
    assert status == (413 if token == TOKEN else 401), answer
    assert client.read == 0 and not app.called


def test_a_raw_token_without_bearer_is_not_a_token():
    headers = [(b"authorization", TOKEN.encode()), length(2)]
    status, _, app = through(scope(headers=headers), Client([b"{}"]))
    assert status == 401 and not app.called


def test_a_declared_body_over_the_limit_is_a_413_unread():
    client = Client([b"x" * 1024])
    status, answer, app = through(scope(headers=[auth(TOKEN), length(LIMIT + 1)]), client)
    assert status == 413 and str(LIMIT) in answer["detail"]
    assert client.read == 0 and not app.called


def test_a_streamed_body_is_cut_off_once_it_passes_the_limit():
    chunk = 1000
    client = Client([b"x" * chunk] * 50)  # no Content-Length: 50 kB streamed
    status, _, app = through(scope(headers=[auth(TOKEN)]), client)
    assert status == 413 and not app.called
    assert client.read == LIMIT // chunk + 1  # read up to the chunk that passed the limit


@pytest.mark.parametrize("chunks", [[b"{}"], [b'{"a":', b" 1", b"}"], [b""]])
def test_a_body_within_the_limit_reaches_the_app_whole_and_a_disconnect_after_it(chunks):
    status, _, app = through(scope(headers=[auth(TOKEN)]), Client(chunks))
    assert status == 200 and app.body == b"".join(chunks)
    assert app.after == "http.disconnect"  # the client's own receive, after the body


@pytest.mark.parametrize(
    ("path", "method"), [("/api/status", "GET"), ("/api/estop", "POST"), ("/", "GET")]
)
def test_reads_and_the_estop_pass_the_door_without_a_token(path, method):
    status, _, app = through(scope(path, method, [length(0)]), Client([b""]))
    assert status == 200 and app.called


def test_no_token_configured_lets_control_requests_through():
    status, _, app = through(scope(headers=[length(2)]), Client([b"{}"]), token=None)
    assert status == 200 and app.body == b"{}"


def test_a_16_mb_body_without_the_token_is_a_401_from_the_server(tmp_path):
    """End to end (the middleware is installed): the 401, not a parse of 16 MB."""
    with make_client(tmp_path, server={"token": TOKEN}) as client:
        body = b'{"position_m": [0, 0, -0.24], "pad": "' + b"x" * HUGE + b'"}'
        response = client.post(
            "/api/goal", content=body, headers={"content-type": "application/json"}
        )
        assert response.status_code == 401, response.text
        response = client.post(
            "/api/goal",
            content=body,
            headers={"content-type": "application/json", "authorization": f"Bearer {TOKEN}"},
        )
        assert response.status_code == 413, response.text
        # the e-stop is never refused at the door, whatever comes with it
        response = client.post("/api/estop", content=body, headers={"content-type": "text/plain"})
        assert response.status_code == 200, response.text
        assert client.get("/api/status").json()["estopped"] is True

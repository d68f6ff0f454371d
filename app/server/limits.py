"""Request limits at the door: the token and the body size are checked before a body is read.

An ASGI middleware, outside FastAPI's routing: a control request (any POST/PUT/PATCH/DELETE
under /api/ but the e-stop) without the right token is a 401 before one byte of its body
is read, and a body over ``server.max_body_bytes`` is a 413, from its Content-Length when it
has one, else as soon as the streamed chunks pass the limit. Without it a 16 MB JSON body
was read and parsed (seconds of GIL held, the control loop's ticks late) before the token
dependency refused it. The route's own dependencies still check the token and the lease:
this is the cheap early refusal, using the same ``token_ok``.
"""

from __future__ import annotations

import json

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.config import Settings
from app.control.authority import token_ok
from app.server.api.deps import bearer

WITH_BODY = frozenset({"POST", "PUT", "PATCH", "DELETE"})
OPEN_TO_ALL = frozenset({"/api/estop"})  # stopping needs no token (the route decides)


def needs_token(scope: Scope) -> bool:
    """A control request: one that may carry a body and change the robot or the server."""
    path = scope["path"]
    return scope["method"] in WITH_BODY and path.startswith("/api/") and path not in OPEN_TO_ALL


def bearer_token(scope: Scope) -> str | None:
    """The token of ``Authorization: Bearer <token>`` (deps.bearer's rule); None otherwise."""
    for name, value in scope["headers"]:
        if name == b"authorization":
            return bearer(value.decode("latin-1"))
    return None


def _content_length(scope: Scope) -> int | None:
    for name, value in scope["headers"]:
        if name == b"content-length":
            try:
                return int(value)
            except ValueError:
                return -1
    return None


async def _refuse(send: Send, status: int, detail: str) -> None:
    body = json.dumps({"detail": detail}).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", b"%d" % len(body))]
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})


class RequestLimits:
    """ASGI middleware: token first, then body size, then the app (see the module doc)."""

    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app = app
        self.settings = settings
        self.max_bytes = settings.server.max_body_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if scope["path"] in OPEN_TO_ALL:  # the e-stop is never refused: its route reads no body
            await self.app(scope, receive, send)
            return
        if needs_token(scope) and not token_ok(self.settings.server.token, bearer_token(scope)):
            await _refuse(send, 401, "missing or wrong token (Authorization: Bearer <token>)")
            return
        length = _content_length(scope)
        if length is not None and length < 0:
            await _refuse(send, 400, "Content-Length is not a number")
            return
        if length is not None and length > self.max_bytes:
            await _refuse(send, 413, self._too_large(f"{length} bytes"))
            return
        first = await self._read_body(receive)
        if first is None:
            await _refuse(send, 413, self._too_large("the streamed body"))
            return
        await self.app(scope, _replay(first, receive), send)

    def _too_large(self, what: str) -> str:
        return f"request body too large: {what}, the limit is {self.max_bytes} bytes"

    async def _read_body(self, receive: Receive) -> Message | None:
        """The whole body as one message, or None once it passes the limit (the rest
        is not read). A disconnect comes back as it is."""
        chunks: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                return message
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.max_bytes:
                return None
            chunks.append(chunk)
            if not message.get("more_body", False):
                return {"type": "http.request", "body": b"".join(chunks), "more_body": False}


def _replay(first: Message, receive: Receive) -> Receive:
    """``first`` once, then the client's own receive (a later disconnect still shows)."""
    pending = [first]

    async def replayed() -> Message:
        return pending.pop() if pending else await receive()

    return replayed

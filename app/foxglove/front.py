"""The token's door in front of the Foxglove server.

Foxglove's WebSocket protocol has no authentication, and foxglove-sdk's server offers no
hook that could refuse a client (its listener hears of subscriptions, never of a
connection). So where ``server.token`` is set, the SDK's server listens on a free
loopback port only, and this front listens where Foxglove was asked to: it takes a client
only with the token, as the API's WebSockets do (``?token=`` in the URL, which the
Foxglove app's connection dialog keeps, or ``Authorization: Bearer <token>``, compared in
constant time), answers any other with HTTP 401 before a byte of the protocol is spoken,
and relays each admitted client's frames to the SDK's server and back, unchanged.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from http import HTTPStatus
from typing import Any
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.client import connect
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response
from websockets.typing import Subprotocol

from app.control.authority import token_ok

log = logging.getLogger(__name__)
# what foxglove-sdk 0.30's server speaks (it refuses the older foxglove.websocket.v1)
SUBPROTOCOLS = (Subprotocol("foxglove.sdk.v1"),)
CLIENT_MAX_BYTES = 1 << 20  # a client sends subscriptions, not data: its largest message
START_TIMEOUT_S = 10.0


class _HandshakeNoise(logging.Filter):
    """A client that speaks no WebSocket or no ``foxglove.sdk.v1`` (a port scan, an old
    client) is its own problem: one INFO line, not an ERROR with a traceback."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.getMessage() == "opening handshake failed":
            exc = record.exc_info[1] if record.exc_info else None
            record.msg, record.args = "Foxglove front: a client's handshake failed: %s", (exc,)
            record.exc_info = record.exc_text = None
            record.levelno, record.levelname = logging.INFO, "INFO"
        return True


_websockets_log = logging.getLogger(f"{__name__}.websockets")
_websockets_log.addFilter(_HandshakeNoise())


def supplied_token(path: str, headers: Headers) -> str | None:
    """The token a client sent: ``?token=`` in its URL, else a Bearer Authorization."""
    query = parse_qs(urlsplit(path).query).get("token")
    if query:
        return query[0]
    scheme, _, value = (headers.get("Authorization") or "").strip().partition(" ")
    return (value.strip() or None) if scheme.lower() == "bearer" else None


class TokenFront:
    """Listens on ``host:port``; relays clients with ``token`` to ``ws://127.0.0.1:
    upstream_port`` (the SDK's server). Runs its own event loop in a thread."""

    def __init__(self, host: str, port: int, upstream_port: int, token: str) -> None:
        self.host, self.upstream = host, f"ws://127.0.0.1:{upstream_port}"
        self._wanted_port, self._token = port, token
        self.port = 0
        self.refused = 0  # clients turned away without the token
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    def start(self) -> None:
        """Listen (raises OSError when the port cannot be had)."""
        self._thread = threading.Thread(target=self._main, name="foxglove-front", daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT_S):
            raise RuntimeError("the Foxglove token front did not start")
        if self._error is not None:
            raise self._error

    def stop(self) -> None:
        loop, stopping = self._loop, self._stopping
        if loop is not None and stopping is not None:
            with contextlib.suppress(RuntimeError):  # its loop already closed
                loop.call_soon_threadsafe(stopping.set)
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def _main(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as exc:  # reported to start(), or logged once running
            if not self._ready.is_set():
                self._error = exc
                self._ready.set()
            else:
                log.exception("the Foxglove token front stopped")

    def _check(self, connection: ServerConnection, request: Request) -> Response | None:
        if token_ok(self._token, supplied_token(request.path, request.headers)):
            return None
        self.refused += 1
        return connection.respond(
            HTTPStatus.UNAUTHORIZED,
            "missing or wrong token (?token= in the URL, or Authorization: Bearer <token>)\n",
        )

    async def _serve(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stopping = asyncio.Event()
        server: Server
        async with serve(
            self._relay,
            self.host,
            self._wanted_port,
            subprotocols=SUBPROTOCOLS,
            process_request=self._check,
            compression=None,  # as the API's WebSockets: deflate costs more than it saves
            max_size=CLIENT_MAX_BYTES,
            logger=_websockets_log,
        ) as server:
            self.port = next(iter(server.sockets)).getsockname()[1]
            self._ready.set()
            await self._stopping.wait()

    async def _relay(self, client: ServerConnection) -> None:
        """One admitted client: a connection of its own to the SDK's server, frames
        passed both ways until either side closes."""
        try:
            upstream = await connect(
                self.upstream,
                subprotocols=[client.subprotocol] if client.subprotocol else None,
                compression=None,
                max_size=None,  # the server's messages are the data: any size it sends
                proxy=None,
            )
        except (OSError, ConnectionClosed, TimeoutError) as exc:
            log.warning("Foxglove front: the live server did not answer: %s", exc)
            await client.close(1011, "the live server did not answer")
            return
        async with upstream:
            pumps = [
                asyncio.create_task(_pump(client, upstream)),
                asyncio.create_task(_pump(upstream, client)),
            ]
            _, pending = await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
            for task in pending:
                task.cancel()
            await asyncio.gather(*pending, return_exceptions=True)
        await client.close()


async def _pump(source: Any, sink: Any) -> None:
    """Every message of ``source`` to ``sink`` as it came (text as text, binary as binary)."""
    with contextlib.suppress(ConnectionClosed):
        async for message in source:
            await sink.send(message)

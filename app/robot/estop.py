"""The robot node's e-stop listener: a press that does not pass through a station.

``POST /estop`` on a port of its own (``server.estop_port``; 0: any free one, in the
node's ``info`` and the station's ``/api/info``), served by a plain HTTP server in a
thread of the robot node, the process that owns the loop (app/robot/node.py). The page
posts to it in parallel with the station's ``POST /api/estop``, with the same press id
(``?press=``), so a press reaches the loop with the station hung (SIGSTOP) or killed;
each side keeps the first arrival of each press, and the station's status shows both.

The listener does one thing: any other path is a 404 and any other method but the CORS
preflight (OPTIONS) and ``GET /ready`` (204, nothing done: the page keeps its kept-alive
connection warm with it, since a fresh connection cost the browser tens of ms under load)
a 501; it reads no body beyond 1 kB (larger: left unread, the connection closed), holds
at most MAX_CONNECTIONS connections, and only the page's own origins (the stations'
dashboard ports) may read its answer. A new connection always gets in: when all are held,
the one that has waited longest since it last finished a request (or opened) is closed
for it, so idle or trickling connections (a slowloris) cannot lock a press out; once a
request's first byte is in, each read of its header waits at most HEADER_TIMEOUT_S.
Stopping needs no token anywhere (whoever sees the robot about to hurt someone may stop
it), so this grants nothing that /api/estop did not.
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
import socket
import threading
import time
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import parse_qs, urlsplit

log = logging.getLogger(__name__)

LISTENER_PATH = "/estop"
READY_PATH = "/ready"  # GET: 204, nothing else; the page keeps its connection warm with it
IDLE_TIMEOUT_S = 30.0  # a kept-alive connection idle this long is closed
MAX_BODY_BYTES = 1024  # a body is never needed; a larger one is not read (connection closed)
MAX_CONNECTIONS = 32  # beyond, the longest-waiting one is closed for the new one
HEADER_TIMEOUT_S = 2.0  # each read of a request's line and headers, after its first byte
_PRESS = re.compile(r"[A-Za-z0-9_-]{1,64}")


@dataclass(frozen=True)
class EstopReceipt:
    """When the last e-stop press arrived: ``received_unix_s``, the wall-clock time [s
    since the epoch] of its first request by whichever path (None: no press since start),
    ``arrivals_unix_s``, when it came by each path (first per path), and ``press``, the
    press's id (None: a request without one)."""

    received_unix_s: float | None = None
    arrivals_unix_s: dict[str, float] = field(default_factory=dict)
    press: str | None = None


class EstopReceipts:
    """The e-stop paths' front door: every request, by any path, is recorded here and
    then stops the loop (``controller.estop()``, idempotent: every request stops).

    One press may come by several paths (the page sends two requests with the same
    ``press`` id): the receipt keeps its first arrival and each path's first. A request
    without a press id is a press of its own. Safe from any thread; the station's record
    (GET /api/status shows :meth:`latest`), not the loop's.
    """

    def __init__(self, controller: Any) -> None:
        self.controller = controller
        self._lock = threading.Lock()
        self._press: str | None = None
        self._latest = EstopReceipt()

    def press(self, via: str, press: str | None = None) -> Future:
        """An e-stop request arrived by path ``via`` ("listener", "middleware", "route"):
        record when, then stop. Returns the e-stop command's Future."""
        now = time.time()
        with self._lock:
            latest = self._latest
            if press is None or press != self._press:
                self._press = press
                self._latest = EstopReceipt(now, {via: now}, press)
            elif via not in latest.arrivals_unix_s:
                self._latest = EstopReceipt(
                    latest.received_unix_s, {**latest.arrivals_unix_s, via: now}, press
                )
        return self.controller.estop()

    def latest(self) -> EstopReceipt:
        """The last press's receipt (immutable; replaced by each new press or path)."""
        return self._latest


def merged(a: EstopReceipt, b: EstopReceipt) -> EstopReceipt:
    """One receipt of two sides' (the station's paths and the node's listener): the same
    press (its id) is one press, first arrival first, each path's arrival kept; different
    presses, the later one's."""
    if a.received_unix_s is None:
        return b
    if b.received_unix_s is None:
        return a
    if a.press is not None and a.press == b.press:
        arrivals = {**b.arrivals_unix_s, **a.arrivals_unix_s}
        for via, when in b.arrivals_unix_s.items():
            arrivals[via] = min(when, arrivals[via])
        return EstopReceipt(min(a.received_unix_s, b.received_unix_s), arrivals, a.press)
    return a if a.received_unix_s >= b.received_unix_s else b


def valid_press(value: str | None) -> str | None:
    """``value`` when it is 1-64 of [A-Za-z0-9_-], else None (a bad press id never refuses
    an e-stop: the request is then a press of its own)."""
    return value if value is not None and _PRESS.fullmatch(value) else None


def press_id(query: str | bytes) -> str | None:
    """The valid ``press`` parameter of a query string, else None."""
    if isinstance(query, bytes):
        query = query.decode("latin-1")
    values = parse_qs(query).get("press", [])
    return valid_press(values[0]) if values else None


class _Handler(BaseHTTPRequestHandler):
    """HTTP/1.1 with keep-alive: the page's connection stays open between presses (a new
    one costs the browser a connect under load), IDLE_TIMEOUT_S at most."""

    server: _Server
    timeout = IDLE_TIMEOUT_S
    protocol_version = "HTTP/1.1"

    def handle_one_request(self) -> None:
        """One request: IDLE_TIMEOUT_S for its first byte, then HEADER_TIMEOUT_S per read
        of the rest; the connection counts as active again once answered."""
        try:
            self.connection.settimeout(IDLE_TIMEOUT_S)
            if not self.rfile.peek(1):  # type: ignore[attr-defined]  # a BufferedReader
                self.close_connection = True
                return
            self.connection.settimeout(HEADER_TIMEOUT_S)
            super().handle_one_request()
        except (ConnectionError, TimeoutError, OSError):
            self.close_connection = True  # gone, closed for a newer one, or too slow
        finally:
            self.server.touch(self.connection)

    def finish(self) -> None:
        with contextlib.suppress(OSError):  # the client left before the answer was flushed
            super().finish()

    def do_POST(self) -> None:  # noqa: N802 (http.server's naming)
        parts = urlsplit(self.path)
        if parts.path != LISTENER_PATH:
            self._skip_body()
            self._answer(404, {"detail": f"only POST {LISTENER_PATH} here"})
            return
        future = self.server.receipts.press("listener", press_id(parts.query))
        self._skip_body()  # after the stop is latched: nothing waits for a body
        try:
            result = future.result(timeout=self.server.answer_timeout_s)
        except FutureTimeout:
            self._answer(503, {"detail": "the control loop did not answer in time"})
        except Exception as exc:  # the loop is not running, a bus error: say so, as a 503
            self._answer(503, {"detail": f"e-stop: {exc}"})
        else:
            self._answer(200, {"result": result})

    def do_GET(self) -> None:  # noqa: N802
        """``GET /ready``: 204 and nothing else (the page's warm connection); else 404."""
        if urlsplit(self.path).path == READY_PATH:
            self._answer(204, None)
        else:
            self._answer(404, {"detail": f"only POST {LISTENER_PATH} here"})

    def do_OPTIONS(self) -> None:  # noqa: N802
        """The CORS preflight (a plain POST without a body needs none; answered anyway)."""
        self._skip_body()
        self._answer(204, None)

    def _skip_body(self) -> None:
        """Read a small body away (keep-alive needs it); a large or chunked one is left
        unread and the connection closed after the answer."""
        if self.headers.get("Transfer-Encoding"):
            self.close_connection = True
            return
        try:
            length = int(self.headers.get("Content-Length") or 0)
        except ValueError:
            length = -1
        if 0 <= length <= MAX_BODY_BYTES:
            if length:
                self.rfile.read(length)
        else:
            self.close_connection = True

    def _answer(self, status: int, body: dict[str, Any] | None) -> None:
        data = b"" if body is None else json.dumps(body, default=str).encode()
        self.send_response(status)
        origin = self.headers.get("Origin")
        if origin is not None and self.server.origin_allowed(origin):
            self.send_header("Access-Control-Allow-Origin", origin)
            self.send_header("Access-Control-Allow-Methods", "POST")
            self.send_header("Vary", "Origin")
        if body is not None:
            self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(data)))
        if self.close_connection:
            self.send_header("Connection", "close")
        self.end_headers()
        if data:
            self.wfile.write(data)

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002
        log.debug("e-stop listener: " + format, *args)


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    receipts: EstopReceipts
    page_port: int
    answer_timeout_s: float

    def __init__(self, address: tuple[str, int], handler: type[_Handler]) -> None:
        super().__init__(address, handler)
        self._lock = threading.Lock()
        self._since: dict[Any, float] = {}  # open connection -> when it last was active

    @property
    def open_connections(self) -> int:
        with self._lock:
            return len(self._since)

    def touch(self, request: Any) -> None:
        with self._lock:
            if request in self._since:
                self._since[request] = time.monotonic()

    def process_request(self, request: Any, client_address: Any) -> None:
        with self._lock:
            evict = None
            if len(self._since) >= MAX_CONNECTIONS:
                evict = min(self._since, key=self._since.__getitem__)
                del self._since[evict]
            self._since[request] = time.monotonic()
        if evict is not None:
            with contextlib.suppress(OSError):  # its thread's read fails and it ends
                evict.shutdown(socket.SHUT_RDWR)
        super().process_request(request, client_address)

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            with self._lock:
                self._since.pop(request, None)

    def origin_allowed(self, origin: str) -> bool:
        """The dashboard's pages: any host name, a station's HTTP port."""
        try:
            parts = urlsplit(origin)
            return parts.scheme in ("http", "https") and parts.port in self.page_ports
        except ValueError:
            return False


class EstopListener:
    """``POST /estop`` on ``host:port`` in a thread of its own (see the module doc).

    receipts: the presses' record, which stops the loop; page_port: the dashboard's HTTP
    port (the origin allowed to read the answers); answer_timeout_s: how long a press
    waits for the loop's answer [s] (the routes' ``server.command_timeout_s``), then a 503.
    ``port`` is the bound one (0 in the config picks a free one). Raises OSError when the
    port cannot be bound.
    """

    def __init__(
        self,
        receipts: EstopReceipts,
        host: str,
        port: int,
        page_port: int,
        answer_timeout_s: float = 2.0,
    ) -> None:
        self._server = _Server((host, port), _Handler)
        self._server.receipts = receipts
        self._server.page_ports = {page_port}
        self._server.answer_timeout_s = answer_timeout_s
        self.port: int = self._server.server_address[1]
        self._thread = threading.Thread(
            target=self._server.serve_forever,
            # shutdown() waits for the serving loop to look at its flag: at most one poll
            kwargs={"poll_interval": 0.02},
            name="deltadash-estop",
            daemon=True,
        )
        self._thread.start()

    def allow_page(self, port: int) -> None:
        """Let the pages of a station on HTTP port ``port`` read the answers too."""
        self._server.page_ports = {*self._server.page_ports, int(port)}

    def close(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(timeout=2.0)

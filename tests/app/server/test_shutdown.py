"""The server stopping with a program check in flight: Ctrl-C stops it at once (the check
workers are killed as the stop begins, not after it waited for the check), and the
request in flight is answered 503 with Retry-After, never 500, after one Ctrl-C or two.

An attacker's trial found both faults: one Ctrl-C waited for the check in flight (up to
programs.check_timeout_s, its worker ignoring SIGINT), and a second one made uvicorn cancel
the request, a 500. Here `deltadash serve` runs as a subprocess whose checks hold 600 s
(tests/support/slow_checks.py), far past every wait below: a server that waited for the
check would be seen not stopping.
"""

from __future__ import annotations

import asyncio
import json
import signal
import threading
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import pytest
from fastapi import FastAPI

from app.server.errors import install_error_handlers
from tests.support import slow_checks
from tests.support.server import WAIT_S, Server, serve, wait_for

START_S = 180.0  # bound on the check's worker starting (spawn, imports) on a loaded machine
PROGRAM = "G21 G90\nG1 F600 X1\nM2"

assert slow_checks.HOLD_S >= 10 * WAIT_S  # waiting for the check would fail every wait


class CheckInFlight:
    """POST /api/programs/check in a thread: its answer (status, headers, body)."""

    def __init__(self, server: Server) -> None:
        self.answer: tuple[Any, ...] | None = None
        body = json.dumps({"gcode": PROGRAM}).encode()
        self.request = urllib.request.Request(
            server.url + "/api/programs/check",
            data=body,
            method="POST",
            headers={"Content-Type": "application/json"},
        )
        self.thread = threading.Thread(target=self._post, daemon=True)
        self.thread.start()

    def _post(self) -> None:
        try:
            with urllib.request.urlopen(self.request, timeout=slow_checks.HOLD_S) as response:
                self.answer = (response.status, response.headers, response.read())
        except urllib.error.HTTPError as exc:
            self.answer = (exc.code, exc.headers, exc.read())
        except OSError as exc:  # no answer at all (the connection closed)
            self.answer = ("no answer", None, repr(exc).encode())

    def result(self) -> tuple[Any, ...]:
        wait_for(lambda: not self.thread.is_alive(), "the check in flight to be answered")
        assert self.answer is not None
        return self.answer


def worker_gone(pid: int) -> bool:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return True
    return "\nState:\tZ" in status  # killed, not yet reaped


def assert_stopping_503(answer: tuple[Any, ...]) -> None:
    status, headers, body = answer
    assert status == 503, (status, body)
    assert int(headers["Retry-After"]) > 0
    assert "the server is stopping" in json.loads(body)["detail"]


def check_in_flight(server: Server, started: Path) -> tuple[CheckInFlight, int]:
    check = CheckInFlight(server)
    wait_for(started.exists, "the check to start in its worker process", START_S)
    return check, int(started.read_text())


@pytest.mark.slow  # a server and a worker process start
def test_ctrl_c_stops_the_server_at_once_and_answers_the_check_in_flight_503(tmp_path):
    started = tmp_path / "started"
    env = {slow_checks.STARTED_ENV: str(started)}
    with serve(tmp_path, preamble=slow_checks.PREAMBLE, **env) as server:
        check, worker = check_in_flight(server, started)
        server.process.send_signal(signal.SIGINT)
        wait_for(
            lambda: server.process.poll() is not None,
            f"the server to stop on Ctrl-C (not {slow_checks.HOLD_S:g} s later, when the "
            "check in flight would end)",
        )
        assert server.process.returncode == 0, server.log.read_text()[-3000:]
        assert_stopping_503(check.result())
        wait_for(lambda: worker_gone(worker), "the check's worker to be killed")


@pytest.mark.slow
def test_a_second_ctrl_c_answers_the_check_in_flight_503_not_500(tmp_path):
    started = tmp_path / "started"
    env = {slow_checks.STARTED_ENV: str(started)}
    with serve(tmp_path, preamble=slow_checks.PREAMBLE, **env) as server:
        check, worker = check_in_flight(server, started)
        server.process.send_signal(signal.SIGINT)
        wait_for(lambda: "Shutting down" in server.log.read_text(), "the server to begin stopping")
        if server.process.poll() is None:  # it may have stopped already: nothing to force
            server.process.send_signal(signal.SIGINT)  # uvicorn: force quit
        wait_for(lambda: server.process.poll() is not None, "the server to stop")
        assert_stopping_503(check.result())
        assert "Internal Server Error" not in server.log.read_text()
        wait_for(lambda: worker_gone(worker), "the check's worker to be killed")


def test_a_request_the_stopping_server_cancels_is_answered_503_with_retry_after():
    """What a second Ctrl-C does to a request still in flight (uvicorn stops waiting and
    the event loop cancels its task): 503 with Retry-After, not uvicorn's 500."""
    app = FastAPI()
    install_error_handlers(app)
    entered = asyncio.Event()

    @app.get("/slow")
    async def slow() -> dict:
        entered.set()
        await asyncio.Event().wait()  # never set: the request waits until cancelled
        return {}

    async def scenario() -> list[dict]:
        sent: list[dict] = []
        scope = {
            "type": "http",
            "asgi": {"version": "3.0"},
            "http_version": "1.1",
            "method": "GET",
            "scheme": "http",
            "path": "/slow",
            "raw_path": b"/slow",
            "root_path": "",
            "query_string": b"",
            "headers": [],
            "client": ("127.0.0.1", 1),
            "server": ("127.0.0.1", 80),
        }

        async def receive() -> dict:
            await asyncio.Event().wait()  # the client sends nothing more
            return {}

        async def send(message: dict) -> None:
            sent.append(message)

        task = asyncio.create_task(app(scope, receive, send))
        await asyncio.wait_for(entered.wait(), WAIT_S)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):  # the cancellation goes on
            await task
        return sent

    sent = asyncio.run(scenario())
    start = next(m for m in sent if m["type"] == "http.response.start")
    headers = {k.decode().lower(): v.decode() for k, v in start["headers"]}
    assert start["status"] == 503
    assert int(headers["retry-after"]) > 0
    body = b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")
    assert "the server is stopping" in json.loads(body)["detail"]

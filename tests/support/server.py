"""`deltadash serve` on the simulator as a subprocess on free ports, spoken to over HTTP.

The 3D scene is off unless asked for (``serve(folder, scene=True)``): only a test that
looks at it should pay for viser starting beside the server.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.support import wait as waiting

# generous: the station, its robot node and viser start slowly on a loaded 2-core machine
START_S = 120.0
# a command's wait for the loop: the product's 2 s is sized for a quiet machine; beside
# CPU hogs a niced test server's loop can be late longer than that (CI saw a 503)
COMMAND_WAIT_S = 10.0
WAIT_S = 60.0  # bound on waiting for an effect (a loaded 2-core machine); not a timing assertion


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def wait_for(
    condition: Callable[[], Any],
    what: str,
    timeout_s: float = WAIT_S,
    *,
    seen: Callable[[], Any] | None = None,
) -> Any:
    """tests.support.wait.wait_for, polling a subprocess server at a gentler 10 Hz."""
    return waiting.wait_for(condition, what, timeout_s, poll_s=0.1, seen=seen)


@dataclass
class Server:
    url: str
    process: subprocess.Popen
    log: Path

    def get(self, path: str) -> Any:
        with urllib.request.urlopen(self.url + path, timeout=10) as response:
            return json.load(response)

    def post(self, path: str, body: dict | None = None) -> Any:
        data = json.dumps(body or {}).encode()
        request = urllib.request.Request(
            self.url + path, data=data, method="POST", headers={"Content-Type": "application/json"}
        )
        with urllib.request.urlopen(request, timeout=10) as response:
            return json.load(response)

    def brief(self) -> dict[str, Any]:
        """What a timed-out wait on the robot should print: mode, torque, e-stop, faults,
        the last notice, the run phase, the measured and commanded points [mm]."""
        try:
            status = self.get("/api/status")
        except (urllib.error.URLError, OSError) as exc:
            return {"status": f"unreadable: {exc}"}

        def mm(v: list | None) -> list | None:
            return None if v is None else [None if c is None else round(1e3 * c, 2) for c in v]

        return {
            "mode": status["mode"],
            "torque": status["torque"],
            "estopped": status["estopped"],
            "faults": [f"{f['source']}: {f['reason']}" for f in status["faults"]],
            "warning": status["warning"],
            "notice": status["notice"],
            "phase": status["phase"],
            "measured_mm": mm(status["ee"]["position_m"]),
            "commanded_mm": mm(status["ee"].get("commanded_m")),
            "loop_hz": status["loop"].get("measured_hz"),
        }

    def up(self) -> bool:
        try:
            self.get("/api/info")  # open even where reads need the token
            return True
        except (urllib.error.URLError, OSError):
            return False


PATIENT_LINK_S = 5.0


PORT_TRIES = 3  # starts of a server whose free port another process took meanwhile


@contextmanager
def serve(folder: Path, scene: bool = False, preamble: str = "", **env: str) -> Iterator[Server]:
    """`deltadash serve` on free ports with runs under ``folder``, the 3D scene on if
    ``scene``; extra DELTADASH_* ``env``; ``preamble``: Python run in the server's process
    before it starts (e.g. tests.support.slow_checks.PREAMBLE).

    A free port is free only when it is looked at: another process (a test worker beside
    this one, a robot node's socket) can bind it before the server does. A server that
    exits saying its address is in use is started again on other ports."""
    log = folder / "serve.log"
    for attempt in range(1, PORT_TRIES + 1):
        served = _start(folder, scene, preamble, env, log)
        if served is not None:
            break
        if attempt == PORT_TRIES:
            pytest.fail(f"deltadash serve found no free port:\n{log.read_text()[-3000:]}")
    process = served.process
    try:
        yield served
    finally:
        process.terminate()
        try:
            process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            process.kill()


def _start(
    folder: Path, scene: bool, preamble: str, extra: dict[str, str], log: Path
) -> Server | None:
    """One start of `deltadash serve` (see :func:`serve`), up; None when it exited because
    a port was taken between the look and its bind; fails the test on any other end."""
    port = free_port()
    env = {
        **os.environ,
        "DELTADASH_SERVER__HTTP_PORT": str(port),
        "DELTADASH_SERVER__VISER_PORT": str(free_port()),
        "DELTADASH_SERVER__SCENE": "true" if scene else "false",
        "DELTADASH_RUNS__FOLDER": str(folder / "runs"),
        "DELTADASH_SERVER__COMMAND_TIMEOUT_S": str(COMMAND_WAIT_S),
        # the station's heartbeat to its robot node (a thread of the served process) waits
        # behind chromium's software WebGL on a loaded 2-core machine: tests of the link's
        # loss set their own (tests/link/)
        "DELTADASH_LINK__STATION_TIMEOUT_S": str(PATIENT_LINK_S),
        **extra,
    }
    code = f"{preamble}\nimport sys; from app.cli import main; sys.exit(main())"
    command = [sys.executable, "-c", code]
    with log.open("wb") as out:
        process = subprocess.Popen([*command, "serve"], env=env, stdout=out, stderr=out)
    served = Server(f"http://127.0.0.1:{port}", process, log)
    end = time.monotonic() + START_S
    while not served.up():
        if process.poll() is not None or time.monotonic() > end:
            said = log.read_text(errors="replace")
            if process.poll() is not None and "address already in use" in said:
                return None
            process.kill()
            process.wait()
            pytest.fail(f"deltadash serve did not start:\n{said[-3000:]}")
        time.sleep(0.2)
    return served

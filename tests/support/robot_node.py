"""`deltadash robot` as a subprocess on a free port, and a station in the test's process.

The link's tests (tests/link/) run real processes over loopback: a robot node here, and
either a station in the test's own process (:func:`station`, a RobotClient over Zenoh)
or ``deltadash serve --robot`` (tests/support/server.py ``serve(..., robot=...)``).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from app.config import load_settings
from app.link.client import RobotClient
from app.link.zenoh_station import StationTransport
from tests.support.server import COMMAND_WAIT_S, free_port

START_S = 120.0  # a node imports MuJoCo and opens its bus: slow on a loaded 2-core machine
READY = "deltadash robot: listening on"


@dataclass
class Node:
    endpoint: str
    process: subprocess.Popen
    log: Path
    env: dict[str, str]

    def text(self) -> str:
        return self.log.read_text(errors="replace")

    def kill(self, signum: int = signal.SIGKILL) -> None:
        self.process.send_signal(signum)


def node_env(**link: Any) -> dict[str, str]:
    """DELTADASH_LINK__* variables for ``link`` settings."""
    return {f"DELTADASH_LINK__{k.upper()}": str(v) for k, v in link.items()}


@contextmanager
def robot_node(
    folder: Path, endpoint: str | None = None, backend: str = "sim", **env: str
) -> Iterator[Node]:
    """``deltadash robot`` on ``endpoint`` (default: a free loopback port); extra
    DELTADASH_* ``env``. Waits for its "listening" line."""
    endpoint = endpoint or f"tcp/127.0.0.1:{free_port()}"
    full = {
        **os.environ,
        "DELTADASH_RUNS__FOLDER": str(folder / "runs"),
        # the test's own station may be starved for a moment on a loaded machine; tests
        # of the station's loss set it short again
        "DELTADASH_LINK__STATION_TIMEOUT_S": "5",
        **env,
    }
    log = folder / f"robot-{endpoint.rsplit(':', 1)[-1]}.log"
    with log.open("wb") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "app.cli", "robot", "--backend", backend, "--listen", endpoint],
            env=full,
            stdout=out,
            stderr=out,
        )
    node = Node(endpoint, process, log, full)
    try:
        end = time.monotonic() + START_S
        while READY not in node.text():
            if process.poll() is not None or time.monotonic() > end:
                pytest.fail(f"deltadash robot did not start:\n{node.text()[-3000:]}")
            time.sleep(0.1)
        yield node
    finally:
        if process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout=15)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


@contextmanager
def station(endpoint: str, take_over: bool = False, **link: Any) -> Iterator[RobotClient]:
    """A station in this process linked to the node at ``endpoint`` (its link taken)."""
    settings = load_settings(
        link={"robot": endpoint, **link}, server={"command_timeout_s": COMMAND_WAIT_S}
    )
    transport = StationTransport(settings.link, endpoint)
    client = RobotClient(settings, transport, take_over=take_over)
    try:
        client.start()
        yield client
    finally:
        client.stop()


class Watcher:
    """What a passive listener on the node's state key sees: the snapshots, in order, with
    when they arrived (time.monotonic() [s])."""

    def __init__(self) -> None:
        self.seen: list[tuple[float, Any]] = []

    @property
    def latest(self) -> Any:
        return self.seen[-1][1] if self.seen else None

    def since(self, t_s: float) -> list[Any]:
        return [snap for when, snap in self.seen if when >= t_s]


@contextmanager
def watch(endpoint: str, prefix: str = "deltadash/robot") -> Iterator[Watcher]:
    """Listen to the node's published state (an independent Zenoh session that commands
    nothing): the robot as it is, whichever station is linked or gone."""
    import zenoh

    from app.config import LinkSettings
    from app.control.state import Snapshot
    from app.link.codec import decode
    from app.link.protocol import Keys
    from app.link.zenoh_session import zenoh_config

    config, cleanup = zenoh_config(LinkSettings(), connect=endpoint)
    session = zenoh.open(config)
    watcher = Watcher()

    def state(sample: Any) -> None:
        watcher.seen.append((time.monotonic(), decode(Snapshot, sample.payload.to_bytes())))
        del watcher.seen[:-20000]

    subscriber = session.declare_subscriber(Keys(prefix).state, state)
    try:
        yield watcher
    finally:
        subscriber.undeclare()
        session.close()
        cleanup()

"""The station's robot: where the loop runs (``link.robot``) and the link to it.

- ``embedded`` (the default): ``deltadash serve`` starts a robot node (``deltadash
  robot``) as its own child process on this machine, with this station's config, links
  to it over Zenoh on loopback, and supervises it: a node that dies is started again
  (and the station takes its link again); the node outlives a station killed without a
  stop only long enough to hold the arm and answer an e-stop (``--orphan-hold-s``).
- a Zenoh endpoint (``tcp/192.168.1.20:7447``): a robot node elsewhere, e.g. on the
  drone's computer (``deltadash robot --listen``).
- ``in-process``: the node in this process, called directly (app/robot/local.py): the
  tests, on simulated time; the station's code is the same.

Whichever it is, the station's handle is a :class:`~app.link.client.RobotClient`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import tomli_w

from app.config import Settings
from app.control.controller import Controller
from app.link.client import RobotClient
from app.link.protocol import RobotOffline
from app.robot.local import LocalTransport
from app.robot.node import RobotNode

log = logging.getLogger(__name__)
EMBEDDED = "embedded"
IN_PROCESS = "in-process"
START_WITHIN_S = 90.0  # a node's first answer (imports MuJoCo, opens the bus) on a loaded machine
RESTART_AFTER_S = 1.0
WATCH_EVERY_S = 0.1


@dataclass
class OpenRobot:
    """The station's robot: its client, and in this process the node and the backend."""

    client: RobotClient
    node: RobotNode | None = None
    backend: Any = None
    child: EmbeddedNode | None = None


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` now (the embedded node listens on it)."""
    with socket.socket() as probe:
        probe.bind((host, 0))
        return int(probe.getsockname()[1])


class EmbeddedNode:
    """``deltadash robot`` as a child process of the station, started again if it dies."""

    def __init__(self, settings: Settings, endpoint: str, on_restart: Callable[[], None]) -> None:
        self.endpoint, self._on_restart = endpoint, on_restart
        handle, path = tempfile.mkstemp(prefix="deltadash-robot-", suffix=".toml")
        with os.fdopen(handle, "wb") as out:  # the station's own settings, whole
            tomli_w.dump(settings.model_dump(mode="json", exclude_none=True), out)
        self.config = Path(path)
        self.restarts = 0
        self._stop = threading.Event()
        self.process = self._spawn()
        self._watch = threading.Thread(target=self._supervise, name="robot-node", daemon=True)
        self._watch.start()

    def _spawn(self) -> subprocess.Popen:
        command = [
            sys.executable,
            "-m",
            "app.cli",
            "robot",
            "--config",
            str(self.config),
            "--listen",
            self.endpoint,
            "--parent",
            str(os.getpid()),
        ]
        return subprocess.Popen(command, stdin=subprocess.DEVNULL)

    def _supervise(self) -> None:
        while not self._stop.wait(WATCH_EVERY_S):
            code = self.process.poll()
            if code is None or self._stop.is_set():
                continue
            log.error("the robot node exited (%s): starting it again", code)
            if self._stop.wait(RESTART_AFTER_S):
                return
            self.process = self._spawn()
            self.restarts += 1
            threading.Thread(target=self._on_restart, daemon=True).start()

    def close(self, timeout_s: float = 10.0) -> None:
        """Stop the node (it stops its loop as its config says) and wait for it."""
        self._stop.set()
        process = self.process
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                log.error("the robot node did not stop within %s s: killed", timeout_s)
                process.kill()
                process.wait()
        self.config.unlink(missing_ok=True)


def _take_link(client: RobotClient, within_s: float) -> None:
    """Take the node's link, trying until it answers or ``within_s`` [s] have passed."""
    deadline = time.monotonic() + within_s
    while True:
        try:
            client.start()
            return
        except RobotOffline:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


@contextlib.contextmanager
def open_robot(settings: Settings, backend_opener: Callable) -> Iterator[OpenRobot]:
    """The robot ``settings.link.robot`` names, linked, for the ``with`` block."""
    where = settings.link.robot
    if where == IN_PROCESS:
        with backend_opener(settings) as backend:
            clock = getattr(backend, "sim_clock", None)  # simulated time (tests drive it)
            controller = Controller(
                settings,
                backend.bus,
                backend.kind,
                backend.description,
                **({} if clock is None else {"clock": clock.now, "tick_clock": clock}),
            )
            node = RobotNode(settings, controller)
            node.start()
            node.start_estop_listener()
            client = RobotClient(settings, LocalTransport(node))
            try:
                client.start()
                yield OpenRobot(client, node, backend)
            finally:
                client.halt()
                unsafe = node.stop()
                if unsafe:
                    log.warning("%s", unsafe)
        return
    from app.link.zenoh_station import StationTransport

    with contextlib.ExitStack() as stack:
        child: EmbeddedNode | None = None
        if where == EMBEDDED:
            endpoint = f"tcp/127.0.0.1:{free_port()}"
            holder: list[RobotClient] = []
            child = EmbeddedNode(settings, endpoint, lambda: _relink(holder))
            stack.callback(child.close)
        else:
            endpoint = where
        transport = StationTransport(settings.link, endpoint)
        stack.callback(transport.close)
        client = RobotClient(settings, transport)
        _take_link(client, START_WITHIN_S)
        if child is not None:
            holder.append(client)
        stack.callback(client.stop)
        yield OpenRobot(client, None, None, child)


def _relink(holder: list[RobotClient]) -> None:
    """A restarted embedded node: take its link again once it answers."""
    if holder:
        try:
            deadline = time.monotonic() + START_WITHIN_S
            while True:
                try:
                    holder[0].reconnect()
                    log.warning("the robot node is back: link taken again")
                    return
                except RobotOffline:
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.2)
        except Exception as exc:
            log.error("the restarted robot node's link was not taken: %s", exc)

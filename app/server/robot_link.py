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
import secrets
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
from app.link.protocol import LinkRefused, RobotOffline
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

    def __init__(self, settings: Settings, endpoint: str) -> None:
        self.endpoint = endpoint
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
            self.process = self._spawn()  # the station takes its link again (client.py)
            self.restarts += 1

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


def embedded_settings(settings: Settings) -> Settings:
    """The settings of a station and its embedded node: a login of their own on the link
    (a random password, when the config gives none: no other process on this machine can
    open a session with the node, as none can use the API without the token), and the
    node's e-stop listener on a port chosen now, which a node started again binds again
    (the page keeps the port it was given)."""
    link, server = settings.link, settings.server
    if link.user is None or link.password is None:
        link = link.model_copy(update={"user": "station", "password": secrets.token_urlsafe(24)})
    if server.estop_listener and server.estop_port == 0:
        host = server.host if server.host not in ("0.0.0.0", "::") else "127.0.0.1"
        server = server.model_copy(update={"estop_port": free_port(host)})
    return settings.model_copy(update={"link": link, "server": server})


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
            settings = embedded_settings(settings)
            child = EmbeddedNode(settings, endpoint)
            stack.callback(child.close)
        else:
            endpoint = where
        transport = StationTransport(settings.link, endpoint)
        stack.callback(transport.close)
        client = RobotClient(settings, transport)
        try:
            _take_link(client, START_WITHIN_S)
        except (RobotOffline, LinkRefused) as exc:
            log.error("deltadash: the robot node at %s: %s", endpoint, exc)
            raise
        stack.callback(client.stop)
        yield OpenRobot(client, None, None, child)

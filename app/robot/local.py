"""A station and a robot node in one process: the link's transport as calls.

The tests' apps (tests/support/app_client.py) and ``deltadash run`` use it: the station's
:class:`~app.link.client.RobotClient` commands an in-process
:class:`~app.robot.node.RobotNode` through the same ops, arguments and answers as over
Zenoh (the arguments cross as JSON), and reads the snapshots the loop publishes, so the
station's code is the same whichever side of a network the loop runs on.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

from app.control.state import Snapshot
from app.robot.node import RobotNode


class LocalTransport:
    """Calls into ``node`` (app/robot/node.py) as one station."""

    def __init__(self, node: RobotNode) -> None:
        self.node = node
        self.station = ""
        self._on_state: Callable[[Snapshot], None] | None = None
        self._on_ticks: Callable[[list[Snapshot]], None] | None = None

    def open(
        self,
        station: str,
        on_state: Callable[[Snapshot], None],
        on_ticks: Callable[[list[Snapshot]], None],
        beat: Callable[[], tuple[int, str] | None],
    ) -> None:
        """(A station in the node's own process is never lost: no heartbeat is sent.)"""
        self.station, self._on_state, self._on_ticks = station, on_state, on_ticks
        self.node.add_tick_listener(self._tick)
        on_state(self.node.controller.snapshot())

    @property
    def node_running(self) -> bool:
        """The node's loop runs (the station is in the same process: never offline)."""
        return self.node.controller.running

    def _tick(self, snap: Snapshot) -> None:
        if self._on_state is None or self._on_ticks is None:
            return
        if self.node.tapped:
            self._on_ticks([snap])
        self._on_state(snap)

    def call(self, op: str, body: bytes, seq: int, mac: str, timeout_s: float) -> Future:
        """``op`` on the node: checked and signed, its arguments parsed from JSON, as they
        would be over the link."""
        try:
            self.node.authorize(self.station, op, seq, mac, body)
            args = json.loads(body)
        except Exception as exc:
            failed: Future = Future()
            failed.set_exception(exc)
            return failed
        return self.node.call(self.station, op, args)

    def node_status(self) -> dict[str, Any]:
        """The node's own status (app/robot/node.py ``status_view``), as it is now."""
        return self.node.status_view()

    def close(self) -> None:
        self._on_state = self._on_ticks = None

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
    ) -> None:
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

    def call(self, op: str, args: dict[str, Any], timeout_s: float) -> Future:
        """``op`` on the node; the arguments cross as JSON, as they would over the link."""
        wire = json.loads(json.dumps(args))
        return self.node.call(self.station, op, wire)

    def node_status(self) -> dict[str, Any]:
        """The node's own status (app/robot/node.py ``status_view``), as it is now."""
        return self.node.status_view()

    def close(self) -> None:
        self._on_state = self._on_ticks = None

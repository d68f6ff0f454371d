"""A station's link to a robot node over Eclipse Zenoh (app/link/client.py Transport).

Keys and messages: app/link/protocol.py; the session: app/link/zenoh_session.py. The
station follows the node's state (latest only), its ticks while it taps them, and its
liveliness token; it says it is alive every ``link.heartbeat_s`` from a thread of its own.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

import zenoh

from app.config import LinkSettings
from app.control.state import Snapshot
from app.link.codec import decode
from app.link.protocol import Keys, RobotOffline, exception_of
from app.link.zenoh_session import zenoh_config

log = logging.getLogger(__name__)
HEARTBEAT_PRIORITY = 40  # below a robot node's loop (50) on the same machine


class StationTransport:
    """A station's link to the robot node at ``endpoint`` (app/link/client.py Transport)."""

    def __init__(self, link: LinkSettings, endpoint: str) -> None:
        self.link, self.keys, self.endpoint = link, Keys(link.key_prefix), endpoint
        config, self._cleanup = zenoh_config(link, connect=endpoint)
        self.session = zenoh.open(config)
        self.station = ""
        self._beat_of: Callable[[], tuple[int, str] | None] = lambda: None
        self._closed = threading.Event()
        self._subscribers: list[Any] = []
        self._heartbeat: threading.Thread | None = None
        self.alive = False
        self.state_received = 0
        self._node_status: dict[str, Any] | None = None

    def open(
        self,
        station: str,
        on_state: Callable[[Snapshot], None],
        on_ticks: Callable[[list[Snapshot]], None],
        beat: Callable[[], tuple[int, str] | None],
    ) -> None:
        self.station, self._beat_of = station, beat

        def state(sample: zenoh.Sample) -> None:
            try:
                snap = decode(Snapshot, sample.payload.to_bytes())
            except ValueError as exc:
                log.warning("robot state not read: %s", exc)
                return
            self.state_received += 1
            on_state(snap)

        def ticks(sample: zenoh.Sample) -> None:
            try:
                batch = [decode(Snapshot, s) for s in json.loads(sample.payload.to_bytes())]
            except ValueError as exc:
                log.warning("robot ticks not read: %s", exc)
                return
            on_ticks(batch)

        def alive(sample: zenoh.Sample) -> None:
            self.alive = sample.kind == zenoh.SampleKind.PUT

        def node(sample: zenoh.Sample) -> None:
            with contextlib.suppress(ValueError):
                self._node_status = json.loads(sample.payload.to_bytes())

        session, keys = self.session, self.keys
        self._subscribers = [
            session.declare_subscriber(keys.state, state),
            session.declare_subscriber(keys.ticks, ticks),
            session.liveliness().declare_subscriber(keys.alive, alive, history=True),
            session.declare_subscriber(keys.node, node),
        ]
        self._heartbeat = threading.Thread(target=self._beat, name="link-heartbeat", daemon=True)
        self._heartbeat.start()

    def _beat(self) -> None:
        # Its silence stops the robot: where the OS allows it (root, CAP_SYS_NICE), it runs
        # SCHED_FIFO, so a loaded station's other work never holds it back (measured: a
        # station beside one CPU hog was silent up to 52 ms of the 60 ms allowed).
        with contextlib.suppress(OSError, AttributeError):
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(HEARTBEAT_PRIORITY))
        publisher = self.session.declare_publisher(
            self.keys.heartbeat(self.station),
            congestion_control=zenoh.CongestionControl.DROP,
            express=True,
            priority=zenoh.Priority.REAL_TIME,
        )
        while not self._closed.wait(self.link.heartbeat_s):
            signed = self._beat_of()
            if signed is None:  # no link taken yet: nothing to say
                continue
            try:
                publisher.put(b"%d:%s" % (signed[0], signed[1].encode()))
            except zenoh.ZError:
                return

    def node_status(self) -> dict[str, Any] | None:
        """The node's own status as it last published it (every 0.1 s); None: none yet."""
        return self._node_status

    def call(self, op: str, body: bytes, seq: int, mac: str, timeout_s: float) -> Future:
        future: Future = Future()
        got: list[Any] = []

        def on_reply(reply: zenoh.Reply) -> None:
            got.append(reply)

        def finish() -> None:  # Zenoh calls the handler's drop once the query is over
            if future.done():
                return
            if not got:
                future.set_exception(
                    RobotOffline(
                        f"the robot node at {self.endpoint} did not answer {op!r} within "
                        f"{timeout_s:g} s"
                    )
                )
                return
            reply = got[0]
            if reply.ok is None:
                future.set_exception(RobotOffline(f"robot node: {reply.err.payload.to_string()}"))
                return
            try:
                message = json.loads(reply.ok.payload.to_bytes())
                if message.get("ok"):
                    future.set_result((message.get("result"), int(message.get("tick", 0))))
                else:
                    future.set_exception(exception_of(message.get("error") or {}))
            except (ValueError, TypeError, AttributeError) as exc:
                future.set_exception(RobotOffline(f"robot node: unreadable answer ({exc})"))

        selector = f"{self.keys.command(op)}?station={self.station};seq={seq};mac={mac}"
        try:
            self.session.get(
                selector,
                zenoh.handlers.Callback(on_reply, finish),
                payload=body,
                timeout=timeout_s,
                target=zenoh.QueryTarget.ALL,
            )
        except zenoh.ZError as exc:
            future.set_exception(RobotOffline(f"the link is closed: {exc}"))
        return future

    def close(self) -> None:
        self._closed.set()
        if self._heartbeat is not None:
            self._heartbeat.join(timeout=1.0)
        with contextlib.suppress(zenoh.ZError):
            self.session.close()
        self._cleanup()

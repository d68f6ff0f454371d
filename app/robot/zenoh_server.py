"""A robot node served over Eclipse Zenoh (the ``deltadash robot`` process).

Keys and messages: app/link/protocol.py; the session: app/link/zenoh_session.py. The
node's state goes out from a thread of its own: the control thread only leaves each
snapshot in a one-slot mailbox (and, while a station taps every tick, in a list), so a
slow network or a slow station never holds a tick.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import threading
import time
from concurrent.futures import Future

import zenoh

from app.config import LinkSettings
from app.control.state import Snapshot
from app.link.codec import encode, plain
from app.link.protocol import MAX_COMMAND_BYTES, Keys, LinkRefused, reply_error
from app.link.zenoh_session import zenoh_config
from app.robot.node import RobotNode
from app.robot.ros import RosNode
from app.ros2 import graph

log = logging.getLogger(__name__)
PUBLISH_EVERY_S = 0.002  # the publisher thread's longest wait for a new snapshot
TICK_BATCH_S = 0.05  # a tapping station gets every tick in batches this often
NODE_STATUS_S = 0.1  # the node's own status (link, e-stop receipt, pose input) this often


class NodeServer:
    """Serves ``node`` on a Zenoh session listening on ``listen``."""

    def __init__(self, node: RobotNode, link: LinkSettings, listen: str) -> None:
        self.node, self.keys = node, Keys(link.key_prefix)
        config, self._cleanup = zenoh_config(link, listen=listen)
        self.session = zenoh.open(config)
        self._latest: Snapshot | None = None
        self._ticks: list[Snapshot] = []
        # the state goes out at most link.state_hz: at a 1 kHz loop, every fifth tick
        self._state_every_s = 1.0 / link.state_hz
        self._state_at = -float("inf")
        self._wake = threading.Event()
        self._closed = threading.Event()
        self._state = self.session.declare_publisher(
            self.keys.state,
            congestion_control=zenoh.CongestionControl.DROP,
            express=True,
            priority=zenoh.Priority.DATA_HIGH,
        )
        self._tick_pub = self.session.declare_publisher(
            self.keys.ticks,
            congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE,
        )
        self._status = self.session.declare_publisher(self.keys.node)
        self._queryable = self.session.declare_queryable(self.keys.commands, self._on_query)
        self._heartbeats = self.session.declare_subscriber(self.keys.heartbeats, self._on_heartbeat)
        self._token = self.session.liveliness().declare_token(self.keys.alive)
        node.add_tick_listener(self._on_tick)
        self._loop_tid = node.controller.thread_native_id() or 0
        # the robot as a ROS 2 node (docs/ros2.md): on this session, where ROS peers connect
        # to the node's endpoint; on a session of its own connected to the ROS graph's
        # router when [ros2] connect names it (the link's keys and login stay off that
        # network)
        endpoints = node.settings.ros2.connect
        self._ros_session = zenoh.open(graph.session_config(endpoints)) if endpoints else None
        self.ros = RosNode(node, self._ros_session or self.session, self._below_loop)
        self._thread = threading.Thread(target=self._publish, name="link-publish", daemon=True)
        self._thread.start()

    # control thread: leave the snapshot, never wait
    def _on_tick(self, snap: Snapshot) -> None:
        tapped = self.node.tapped
        if tapped:
            self._ticks.append(snap)
        if snap.time_s - self._state_at >= self._state_every_s - 1e-6:
            self._state_at = snap.time_s
            self._latest = snap
            self._wake.set()
        elif tapped and len(self._ticks) == 1:
            self._wake.set()

    def _below_loop(self) -> None:
        # A publishing thread holds the GIL while it encodes: preempted then by a process
        # of the station's, it would keep the loop's real-time thread waiting for the GIL
        # (priority inversion). Where the loop got SCHED_FIFO, it asks for it too, below.
        with contextlib.suppress(OSError, AttributeError):
            if os.sched_getscheduler(self._loop_tid) == os.SCHED_FIFO:
                below = max(1, os.sched_getparam(self._loop_tid).sched_priority - 10)
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(below))

    def _publish(self) -> None:
        self._below_loop()
        last_batch = last_status = time.monotonic()
        while not self._closed.is_set():
            self._wake.wait(PUBLISH_EVERY_S)
            self._wake.clear()
            snap, self._latest = self._latest, None
            try:
                if snap is not None:
                    self._state.put(encode(snap))
                now = time.monotonic()
                if self._ticks and (now - last_batch >= TICK_BATCH_S or not self.node.tapped):
                    batch, self._ticks = self._ticks, []
                    self._tick_pub.put(b"[" + b",".join(encode(s) for s in batch) + b"]")
                    last_batch = now
                if now - last_status >= NODE_STATUS_S:
                    self._status.put(json.dumps(plain(self.node.status_view())).encode())
                    last_status = now
            except zenoh.ZError as exc:  # the session is closing
                log.debug("link publish: %s", exc)

    # Zenoh's threads
    def _on_heartbeat(self, sample: zenoh.Sample) -> None:
        station = str(sample.key_expr).rsplit("/", 1)[-1]
        seq, _, mac = sample.payload.to_bytes()[:200].decode(errors="replace").partition(":")
        if seq.isdigit():
            self.node.heartbeat(station, int(seq), mac)  # kept only if the holder signed it

    def _on_query(self, query: zenoh.Query) -> None:
        op = str(query.key_expr).rsplit("/", 1)[-1]
        params = query.parameters
        station, mac = params.get("station") or "", params.get("mac") or ""
        key = query.key_expr
        try:
            seq_text = params.get("seq") or "0"
            seq = int(seq_text) if seq_text.isdigit() else -1
            size = len(query.payload) if query.payload is not None else 0
            if size > MAX_COMMAND_BYTES:  # refused unread: parsing it would hold the loop
                raise ValueError(f"args: {size} bytes, more than {MAX_COMMAND_BYTES}")
            raw = query.payload.to_bytes() if query.payload is not None else b""
            # who may send this, before its body is read (the signature covers the body)
            self.node.authorize(station, op, seq, mac, raw)
            args = json.loads(raw or b"{}")
        except (ValueError, LinkRefused) as exc:
            if isinstance(exc, json.JSONDecodeError):
                exc = ValueError(f"args: not JSON ({exc})")
            query.reply(key, reply_error(exc))
            query.drop()
            return
        answered = self.node.call(station, op, args)

        def reply(done: Future) -> None:
            try:
                error = done.exception()
                if error is not None:
                    query.reply(key, reply_error(error))
                else:
                    result, tick = done.result()
                    body = {"ok": True, "result": result, "tick": tick}
                    query.reply(key, json.dumps(body, separators=(",", ":")).encode())
            except zenoh.ZError as exc:
                log.debug("link reply: %s", exc)
            finally:
                query.drop()

        answered.add_done_callback(reply)

    def close(self) -> None:
        self._closed.set()
        self._wake.set()
        self._thread.join(timeout=2.0)
        self.ros.close()
        if self._ros_session is not None:
            self._ros_session.close()
        with contextlib.suppress(zenoh.ZError):
            self._token.undeclare()
        self.session.close()
        self._cleanup()

"""The robot's ROS 2 topics, published on a Zenoh session (the robot node's).

A ROS 2 node (``[ros2] node_name`` in ``namespace``) with publishers of
``sensor_msgs/JointState``, ``/tf``, ``/tf_static``, the tip's ``PoseStamped`` in the base
frame and in the world while holding, its contact force (``geometry_msgs/WrenchStamped``,
docs/contact.md) and ``diagnostic_msgs/DiagnosticArray``
(app/ros2/messages.py), on rmw_zenoh's keys with its liveliness tokens and attachments
(app/ros2/graph.py), or on zenoh-bridge-ros2dds's keys (``form`` bridge).

The control thread only leaves each tick's snapshot and its wall time in a one-slot
mailbox (:meth:`RosPublisher.offer`) and, ``rate_hz`` times a second, wakes a thread of
this publisher that encodes and sends it (diagnostics once a second, and at once when
their level changes): ROS costs the tick an assignment and, now and then, an event set.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import zenoh
import zenoh.ext

from app.config import Settings
from app.control.state import Snapshot
from app.ros2 import graph
from app.ros2.messages import (
    DIAGNOSTICS,
    JOINT_STATE,
    POSE,
    TF,
    WRENCH,
    Messages,
    diagnostic_level,
    type_hash,
)

log = logging.getLogger(__name__)
DIAGNOSTICS_EVERY_S = 1.0  # ROS's diagnostics convention: 1 Hz (and on a change of level)
TF_STATIC_EVERY_S = 5.0  # /tf_static again for subscribers that joined without history
IDLE_WAKE_S = 0.5  # with no ticks (a stopped loop), the thread still wakes this often


@dataclass
class Topic:
    """One publisher: its key, type, GID and sequence number."""

    name: str  # fully qualified
    typename: str
    key: str
    type_hash: str
    gid: bytes = field(default_factory=graph.new_gid)
    sequence: int = 0
    sent: int = 0
    publisher: Any = None


class RosPublisher:
    """Publishes the robot's topics on ``session`` from a thread of its own, as ROS 2
    node ``node`` (its publishers numbered from ``entity_ids``).

    ``thread_setup``: called first in that thread (e.g. to give it a real-time priority
    below the loop's); ``extra_diagnostics``: more key-values for the diagnostics (the
    ROS inputs' counters), called in that thread; ``world_frame``: the world's frame id
    for the tip in the world (default ``[ros2] world_frame``)."""

    def __init__(
        self,
        session: zenoh.Session,
        settings: Settings,
        node: graph.GraphNode,
        entity_ids: Iterator[int],
        thread_setup: Callable[[], None] | None = None,
        extra_diagnostics: Callable[[], dict[str, str]] | None = None,
        world_frame: Callable[[], str] | None = None,
    ) -> None:
        self.session, self.settings, self.ros = session, settings, settings.ros2
        self.messages = Messages(settings)
        self._setup = thread_setup
        self._extra = extra_diagnostics or dict
        self._world_frame = world_frame or (lambda: settings.ros2.world_frame)
        self._latest: tuple[Snapshot, float] | None = None
        self._period_s = 1.0 / settings.ros2.rate_hz
        self._due_s = 0.0
        self._wake = threading.Event()
        self._closed = threading.Event()
        ros = self.ros
        self.node, self._entity_ids = node, entity_ids
        self._tokens: list[Any] = []
        self.joint_states = self._declare(ros.joint_states_topic, JOINT_STATE)
        self.tf = self._declare("/tf", TF)
        self.tf_static = self._declare("/tf_static", TF, transient_local=True)
        self.tip_pose = self._declare(ros.tip_pose_topic, POSE)
        self.tip_world = self._declare(ros.tip_world_topic, POSE)
        self.diagnostics = self._declare(ros.diagnostics_topic, DIAGNOSTICS)
        self.tip_wrench = self._declare(ros.tip_wrench_topic, WRENCH)
        self._thread = threading.Thread(target=self._run, name="ros2-publish", daemon=True)
        self._thread.start()

    @property
    def topics(self) -> list[Topic]:
        return [
            self.joint_states,
            self.tf,
            self.tf_static,
            self.tip_pose,
            self.tip_world,
            self.diagnostics,
            self.tip_wrench,
        ]

    def _declare(self, name: str, typename: str, transient_local: bool = False) -> Topic:
        ros = self.ros
        topic_name = graph.qualified(ros.namespace, ros.node_name, name)
        hashed = type_hash(ros.distro, typename) if ros.distro != "humble" else graph.NO_HASH
        key = graph.topic_key(ros.form, ros.domain_id, topic_name, typename, hashed)
        topic = Topic(topic_name, typename, key, hashed)
        if transient_local:  # late joiners get the last sample (rmw_zenoh: a cache)
            topic.publisher = zenoh.ext.declare_advanced_publisher(
                self.session,
                key,
                cache=zenoh.ext.CacheConfig(max_samples=1),
                publisher_detection=True,
            )
        else:
            topic.publisher = self.session.declare_publisher(
                key, congestion_control=zenoh.CongestionControl.DROP
            )
        if ros.form == "rmw_zenoh":
            qos = graph.encode_qos(True, transient_local, 1 if transient_local else 10)
            token = self.node.endpoint_token(
                next(self._entity_ids), "publisher", topic_name, typename, hashed, qos
            )
            self._tokens.append(self.session.liveliness().declare_token(token))
        return topic

    # the control thread: leave the snapshot, never wait
    def offer(self, snap: Snapshot, wall_s: float) -> None:
        """The latest tick's snapshot and its wall time [s since the epoch]; the publishing
        thread wakes for it when ``1 / rate_hz`` has passed since the last it sent."""
        self._latest = (snap, wall_s)
        if wall_s >= self._due_s:
            self._due_s = wall_s + self._period_s - 0.5e-3  # a tick early is still due
            self._wake.set()

    def _put(self, topic: Topic, message: Any, stamp_s: float) -> None:
        payload = self.messages.cdr(message, topic.typename)
        if self.ros.form == "rmw_zenoh":
            extra = graph.attachment(topic.sequence, int(stamp_s * 1e9), topic.gid)
            topic.publisher.put(payload, encoding="application/cdr", attachment=extra)
        else:
            topic.publisher.put(payload, encoding="application/cdr")
        topic.sequence += 1
        topic.sent += 1

    @staticmethod
    def _wanted(topic: Topic) -> bool:
        """Whether a subscriber matches ``topic`` now (a cached one, /tf_static: always)."""
        status = getattr(topic.publisher, "matching_status", None)
        return status is None or bool(status.matching)

    def _run(self) -> None:
        if self._setup is not None:
            with contextlib.suppress(Exception):
                self._setup()
        messages = self.messages
        diagnostics_at = static_at = -float("inf")
        level = None
        while not self._closed.is_set():
            self._wake.wait(IDLE_WAKE_S)  # a tick that is due, or /tf_static's turn
            self._wake.clear()
            latest, self._latest = self._latest, None
            now = time.time()
            try:
                if now - static_at >= TF_STATIC_EVERY_S:
                    self._put(self.tf_static, messages.tf_static(now), now)
                    static_at = now
                if latest is None:
                    continue
                snap, stamp = latest
                # a message nobody subscribes to is not built (Zenoh knows who matches)
                if self._wanted(self.joint_states):
                    self._put(self.joint_states, messages.joint_state(snap, stamp), stamp)
                if self._wanted(self.tf) and (tf := messages.tf(snap, stamp)) is not None:
                    self._put(self.tf, tf, stamp)
                if (
                    self._wanted(self.tip_pose)
                    and (tip := messages.tip_pose(snap, stamp)) is not None
                ):
                    self._put(self.tip_pose, tip, stamp)
                if (
                    self._wanted(self.tip_world)
                    and (world := messages.tip_world(snap, stamp, self._world_frame())) is not None
                ):
                    self._put(self.tip_world, world, stamp)
                if (
                    self._wanted(self.tip_wrench)
                    and (wrench := messages.tip_wrench(snap, stamp)) is not None
                ):
                    self._put(self.tip_wrench, wrench, stamp)
                now_level = diagnostic_level(snap)[0]
                due = now - diagnostics_at >= DIAGNOSTICS_EVERY_S or now_level != level
                if due and self._wanted(self.diagnostics):
                    diagnostics = messages.diagnostics(snap, stamp, self._extra())
                    self._put(self.diagnostics, diagnostics, stamp)
                if due:
                    diagnostics_at, level = now, now_level
            except zenoh.ZError as exc:  # the session is closing
                log.debug("ros2 publish: %s", exc)
            except Exception:  # a message that cannot be built must not end the thread
                log.exception("ros2 publish")

    def view(self) -> dict[str, Any]:
        """The publishers: each topic's name, type, key and samples sent."""
        return {
            "node": f"{self.ros.namespace.rstrip('/')}/{self.ros.node_name}",
            "form": self.ros.form,
            "distro": self.ros.distro,
            "topics": [
                {"name": t.name, "type": t.typename, "key": t.key, "sent": t.sent}
                for t in self.topics
            ],
        }

    def close(self) -> None:
        self._closed.set()
        self._wake.set()
        self._thread.join(timeout=2.0)
        for item in [*self._tokens, *(t.publisher for t in self.topics)]:
            with contextlib.suppress(zenoh.ZError, AttributeError):
                item.undeclare()

"""A run's log as a ROS 2 bag: ``log.ros2.mcap`` beside ``log.mcap`` (docs/ros2.md, "Run
logs as ROS 2 data").

The same ticks as the JSON log, as standard ROS 2 messages (app/ros2/messages.py: the
types and CDR of ``rosbags``' type store for ``[ros2] distro``), in an MCAP file of the
``ros2`` profile: every schema ``ros2msg`` (the type's definition with its dependencies,
as rosbag2 writes it), every channel ``cdr``, with rosbag2's channel metadata
(``offered_qos_profiles``; ``topic_type_hash`` from Jazzy on). So Foxglove, PlotJuggler,
``rosbags`` and ``ros2 bag`` open it as typed data with its frames.

A file of its own, not channels in ``log.mcap``: no one MCAP file holding the JSON channel
opens in all of them. ``rosbags`` (0.11) refuses a file whose profile is not ``ros2`` and
any ``jsonschema`` schema; rosbag2 (``ros2 bag``) refuses a channel without a schema; and
Foxglove refuses a ``json`` channel whose schema is anything but ``jsonschema``.

Topics (names from ``[ros2]``, resolved in its namespace as the live publisher does):
``sensor_msgs/JointState``, ``/tf`` (base -> platform -> tip), ``/tf_static`` (the drone's
body -> the base, once at the start), the tip's ``geometry_msgs/PoseStamped`` in the base
frame and, while holding in the world, in the world frame, the goal the loop tracks (a
PoseStamped in the base frame, when there is one) and ``diagnostic_msgs/DiagnosticArray``
every ``DIAGNOSTICS_EVERY_S`` of log time and at each change of level. Each message's log
and publish time is the JSON tick's (UTC wall clock, app/runs/logs.py) and its header's
stamp the same instant, to the nanosecond, so both logs lie on one timeline.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from mcap.writer import CompressionType, Writer
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2.metadata import dump_qos_v8

from app.config import Settings
from app.control.state import Snapshot
from app.ros2.graph import qualified
from app.ros2.messages import (
    DIAGNOSTICS,
    JOINT_STATE,
    POSE,
    TF,
    Messages,
    diagnostic_level,
    type_hash,
)

FILE = "log.ros2.mcap"
PROFILE = "ros2"  # MCAP's well-known profile of ROS 2 bags
DIAGNOSTICS_EVERY_S = 0.1
_INFINITE = QosTime(9223372036, 854775807)  # RMW_DURATION_INFINITE


def offered_qos(transient_local: bool = False) -> str:
    """rosbag2's ``offered_qos_profiles`` channel metadata of one reliable publisher (the
    form of bags without serialized metadata: rosbag2 reads them as version 8)."""
    durability = QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE
    qos = Qos(
        QosHistory.UNKNOWN,  # as rosbag2 records an offer: history is not discovered
        0,
        QosReliability.RELIABLE,
        durability,
        _INFINITE,
        _INFINITE,
        QosLiveliness.AUTOMATIC,
        _INFINITE,
        False,
    )
    return dump_qos_v8([qos])


@dataclass
class _Channel:
    id: int
    typename: str
    sequence: int = 0


class Ros2Log:
    """Writes the ROS 2 channels of one run into ``file`` (an unchunked, uncompressed MCAP
    writer over it: the caller commits the bytes, as RunLog does its JSON log)."""

    def __init__(self, file: BinaryIO, settings: Settings, metadata: dict[str, str]) -> None:
        self.messages = Messages(settings)
        self.ros = ros = settings.ros2
        self._types = self.messages.types
        self._writer = Writer(file, use_chunking=False, compression=CompressionType.NONE)
        self._writer.start(profile=PROFILE, library="deltadash")
        self._writer.add_metadata("run", metadata)
        self._schemas: dict[str, int] = {}
        self.channels: dict[str, _Channel] = {}  # by topic
        self.joint_states = self._channel(ros.joint_states_topic, JOINT_STATE)
        self.tf = self._channel("/tf", TF)
        self.tf_static = self._channel("/tf_static", TF, transient_local=True)
        self.tip_pose = self._channel(ros.tip_pose_topic, POSE)
        self.tip_world = self._channel(ros.tip_world_topic, POSE)
        self.goal = self._channel(ros.tracked_goal_topic, POSE)
        self.diagnostics = self._channel(ros.diagnostics_topic, DIAGNOSTICS)
        self._static_written = False
        self._diagnostics_ns: int | None = None
        self._level: int | None = None

    def _channel(self, name: str, typename: str, transient_local: bool = False) -> _Channel:
        ros = self.ros
        if typename not in self._schemas:
            text, _ = self.messages.store.generate_msgdef(typename, ros_version=2)
            self._schemas[typename] = self._writer.register_schema(
                typename, "ros2msg", text.encode()
            )
        metadata = {"offered_qos_profiles": offered_qos(transient_local)}
        if ros.distro != "humble":  # Humble has no type hashes
            metadata["topic_type_hash"] = type_hash(ros.distro, typename)
        topic = qualified(ros.namespace, ros.node_name, name)
        channel_id = self._writer.register_channel(topic, "cdr", self._schemas[typename], metadata)
        self.channels[topic] = channel = _Channel(channel_id, typename)
        return channel

    def write(self, snap: Snapshot, stamp_ns: int) -> None:
        """One tick's messages at ``stamp_ns`` [ns, UTC]: log time, publish time and the
        headers' stamp."""
        messages, stamp_s = self.messages, stamp_ns / 1e9
        if not self._static_written:
            self._put(self.tf_static, messages.tf_static(stamp_s), stamp_ns)
            self._static_written = True
        self._put(self.joint_states, messages.joint_state(snap, stamp_s), stamp_ns)
        for channel, message in (
            (self.tf, messages.tf(snap, stamp_s)),
            (self.tip_pose, messages.tip_pose(snap, stamp_s)),
            (self.tip_world, messages.tip_world(snap, stamp_s)),
            (self.goal, self._goal(snap)),
        ):
            if message is not None:
                self._put(channel, message, stamp_ns)
        level = diagnostic_level(snap)[0]
        since = self._diagnostics_ns
        if since is None or stamp_ns - since >= DIAGNOSTICS_EVERY_S * 1e9 or level != self._level:
            self._put(self.diagnostics, messages.diagnostics(snap, stamp_s), stamp_ns)
            self._diagnostics_ns, self._level = stamp_ns, level

    def _goal(self, snap: Snapshot) -> Any | None:
        """The goal the loop tracks: the tip in the base frame, turned about z by the wrist
        angle it is to hold; None without a goal."""
        goal = np.asarray(snap.goal_m, dtype=float)
        if not np.isfinite(goal).all():
            return None
        angles = (snap.phi_goal_rad, snap.phi_commanded_rad, snap.phi_rad)
        phi = next((float(a) for a in angles if math.isfinite(a)), 0.0)
        t = self._types
        x, y, z = (float(v) for v in goal)
        point = t["geometry_msgs/msg/Point"](x=x, y=y, z=z)
        turn = t["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(phi / 2), w=math.cos(phi / 2)
        )
        header = t["std_msgs/msg/Header"](stamp=None, frame_id=self.ros.base_frame)
        pose = t["geometry_msgs/msg/Pose"](position=point, orientation=turn)
        return t[POSE](header=header, pose=pose)

    def _put(self, channel: _Channel, message: Any, stamp_ns: int) -> None:
        # the headers' stamp exactly the log time (the builders take seconds as a float,
        # whose ulp at today's epoch is ~0.24 us)
        stamp = self._types["builtin_interfaces/msg/Time"](
            sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9
        )
        transforms = getattr(message, "transforms", None)  # a TFMessage: each its own header
        for stamped in [message] if transforms is None else transforms:
            stamped.header.stamp = stamp
        data = self.messages.cdr(message, channel.typename)
        self._writer.add_message(channel.id, stamp_ns, data, stamp_ns, channel.sequence)
        channel.sequence += 1

    def finish(self) -> None:
        """The summary (what readers seek by) and the footer; the caller commits them."""
        self._writer.finish()

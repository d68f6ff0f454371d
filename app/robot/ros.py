"""The robot node as a ROS 2 node on its Zenoh session (docs/ros2.md).

It publishes the robot's topics (app/ros2/publisher.py, ``[ros2] publish``) and, each
opt-in, takes the drone's pose for hold-in-world and tip goals from ROS topics
(app/robot/ros_inputs.py). A ROS goal input is a client like any other: the config must
name it (``goal_input``) and the station that holds the link must arm it (op
``ros_goals``, which the API gives only to the holder of the control lease); it is disarmed
when that station loses or hands over the link. Each goal is checked as the API's are
(the gate, a procedure that holds the robot), and every refusal is counted by reason,
named in the node's status and in the diagnostics topic. An input that goes quiet is named
silent. Nothing a subscription receives can end it: each message is decoded and checked
in a guard, and too many too fast are dropped (``max_input_hz``).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import zenoh

from app.control.errors import GoalRejected, MotionRefused
from app.link.protocol import LinkRefused
from app.robot.ros_inputs import (
    GoalIn,
    InputRefused,
    check_stamp,
    decode,
    goal_from,
    pose_from_odometry,
    pose_from_pose_stamped,
    pose_from_px4,
)
from app.ros2 import graph
from app.ros2.messages import ODOMETRY, POINT, POSE, PX4_ODOMETRY, typestore
from app.ros2.publisher import RosPublisher
from app.world.hold import HoldSource
from app.world.poses import make_sample
from kinematics import Pose, PoseError

if TYPE_CHECKING:
    from app.robot.node import RobotNode

log = logging.getLogger(__name__)
MAX_MESSAGE_BYTES = 8 * 1024  # an odometry is ~700 bytes: anything this big is refused
DECODE_BUDGET = 2.0  # an input decodes at most this many times max_input_hz per second
POSE_TYPES = {"odometry": ODOMETRY, "pose": POSE, "px4": PX4_ODOMETRY}
POSE_TOPICS = {
    "odometry": "odom",
    "pose": "mavros/local_position/pose",
    "px4": "/fmu/out/vehicle_odometry",
}
GOAL_TYPES = {"pose": POSE, "point": POINT}


class Input:
    """One subscription's counts: received, accepted, refused by reason (the last
    refusal's text), dropped as too fast, and when the last message came."""

    def __init__(self, topic: str, typename: str, max_hz: float, silent_s: float) -> None:
        self.topic, self.typename = topic, typename
        self.min_gap_s, self.silent_s = 1.0 / max_hz, silent_s
        self.received = self.accepted = self.flood = self.undecoded = 0
        # a token bucket of decodes: a flood beyond it is dropped before its bytes are read
        self._budget = self._tokens = DECODE_BUDGET * max_hz
        self._filled_s = time.monotonic()
        self.refused: dict[str, int] = {}
        self.last_refusal: str | None = None
        self._last_s: float | None = None
        self._lock = threading.Lock()

    def arrive(self) -> bool:
        """Count a message; False (counted in ``undecoded``) when the input has decoded
        ``DECODE_BUDGET`` times ``max_input_hz`` messages in the last second: a flood
        costs the node (and its loop, which shares the interpreter) no more than that."""
        now = time.monotonic()
        with self._lock:
            self.received += 1
            self._tokens = min(self._budget, self._tokens + (now - self._filled_s) * self._budget)
            self._filled_s = now
            if self._tokens < 1.0:
                self.undecoded += 1
                return False
            self._tokens -= 1.0
            return True

    def admit(self) -> None:
        """A message that passed its checks: InputRefused ("too_fast", counted apart) when
        it came sooner than ``1 / max_input_hz`` after the last one admitted. Only good
        messages count against the rate: a flood of bad ones cannot crowd out good ones."""
        now = time.monotonic()
        with self._lock:
            if self._last_s is not None and now - self._last_s < self.min_gap_s:
                self.flood += 1
                raise InputRefused("too_fast", "")
            self._last_s = now

    def refuse(self, key: str, text: str) -> None:
        with self._lock:
            self.refused[key] = self.refused.get(key, 0) + 1
            self.last_refusal = text

    def accept(self) -> None:
        with self._lock:
            self.accepted += 1

    def state(self) -> str:
        """none (nothing yet), ok, or silent (nothing for ``silent_s``)."""
        if self._last_s is None:
            return "none"
        return "silent" if time.monotonic() - self._last_s > self.silent_s else "ok"

    def view(self) -> dict[str, Any]:
        age = None if self._last_s is None else time.monotonic() - self._last_s
        return {
            "topic": self.topic,
            "type": self.typename,
            "state": self.state(),
            "age_s": age,
            "received": self.received,
            "accepted": self.accepted,
            "refused": dict(self.refused),
            "dropped_too_fast": self.flood,
            "dropped_undecoded": self.undecoded,
            "last_refusal": self.last_refusal,
        }


class RosNode:
    """``node``'s ROS 2 side on ``session`` (``thread_setup``: for the publisher's
    thread)."""

    def __init__(
        self,
        node: RobotNode,
        session: zenoh.Session,
        thread_setup: Callable[[], None] | None = None,
    ) -> None:
        self.node, self.session = node, session
        self.settings = node.settings
        ros = self.ros = node.settings.ros2
        self.store = typestore(ros.distro)
        self.graph = graph.GraphNode(
            ros.domain_id, str(session.info.zid()), 0, ros.namespace, ros.node_name
        )
        self._entities = itertools.count(1)
        self._tokens: list[Any] = []
        self._subscribers: list[Any] = []
        self.armed_by: str | None = None
        self.pose_frame: str | None = None  # the ROS pose input's world frame, once seen
        self.pose: Input | None = None
        self.goal: Input | None = None
        active = ros.publish or ros.pose_input != "off" or ros.goal_input != "off"
        if active and ros.form == "rmw_zenoh":
            self._tokens.append(session.liveliness().declare_token(self.graph.token()))
        self.publisher: RosPublisher | None = None
        if ros.publish:
            self.publisher = RosPublisher(
                session,
                node.settings,
                self.graph,
                self._entities,
                thread_setup,
                self.diagnostics,
                self.world_frame,
            )
            publisher = self.publisher
            node.add_tick_listener(lambda snap: publisher.offer(snap, time.time()))
        if ros.pose_input != "off":
            typename = POSE_TYPES[ros.pose_input]
            name = ros.pose_topic or POSE_TOPICS[ros.pose_input]
            self.pose = self._subscribe(name, typename, self._on_pose, best_effort=True)
        if ros.goal_input != "off":
            self.goal = self._subscribe(
                ros.goal_topic, GOAL_TYPES[ros.goal_input], self._on_goal, best_effort=False
            )
        node.ros = self

    def _subscribe(
        self, name: str, typename: str, handle: Callable[[Any, Input], None], best_effort: bool
    ) -> Input:
        ros = self.ros
        topic = graph.qualified(ros.namespace, ros.node_name, name)
        counts = Input(topic, typename, ros.max_input_hz, ros.input_silent_s)
        hashed = graph.NO_HASH if ros.distro == "humble" else str(self.store.hash_rihs01(typename))
        # rmw_zenoh matches on the type hash; PX4's messages change with its versions (the
        # fields this reads stay): any hash for those, the decoding checks the bytes
        key = graph.topic_key(
            ros.form, ros.domain_id, topic, typename, "*" if typename == PX4_ODOMETRY else hashed
        )

        def on_sample(sample: zenoh.Sample) -> None:
            try:  # nothing a sample carries may end the subscription
                if not counts.arrive():
                    return
                size = len(sample.payload)
                if size > MAX_MESSAGE_BYTES:
                    raise InputRefused("size", f"{size} bytes, more than {MAX_MESSAGE_BYTES}")
                handle(decode(self.store, typename, sample.payload.to_bytes()), counts)
                counts.accept()
            except InputRefused as exc:
                if exc.key != "too_fast":  # counted by admit
                    counts.refuse(exc.key, str(exc))
            except (GoalRejected, MotionRefused, LinkRefused, PoseError, ValueError) as exc:
                counts.refuse(type(exc).__name__, str(exc)[:300])
            except Exception as exc:  # a bug, not the sender's: counted, logged, kept alive
                log.exception("ros2 input %s", topic)
                counts.refuse("error", f"{type(exc).__name__}: {exc}"[:300])

        self._subscribers.append(self.session.declare_subscriber(key, on_sample))
        if ros.form == "rmw_zenoh":
            qos = graph.encode_qos(reliable=not best_effort, depth=10)
            token = self.graph.endpoint_token(
                next(self._entities), "subscription", topic, typename, hashed, qos
            )
            self._tokens.append(self.session.liveliness().declare_token(token))
        return counts

    # Zenoh's threads
    def _on_pose(self, msg: Any, counts: Input) -> None:
        ros = self.ros
        kind = ros.pose_input
        if kind == "odometry":
            pose = pose_from_odometry(msg, ros.input_world_frames, ros.drone_frame)
        elif kind == "pose":
            pose = pose_from_pose_stamped(msg, ros.input_world_frames)
        else:
            pose = pose_from_px4(msg)
        try:
            check_stamp(pose.t_s, time.time(), ros.stamp_future_s, ros.stamp_age_s)
        except InputRefused as exc:
            if kind == "px4" and exc.key == "old" and pose.t_s < 1e9:
                raise InputRefused(
                    "old",
                    f"timestamp: {pose.t_s:.1f} s, PX4's time since boot: turn on the "
                    "bridge's time sync (UXRCE_DDS_SYNCT) or sync the clocks",
                ) from None
            raise
        sample = make_sample(
            pose.t_s,
            pose.position_m,
            pose.quaternion,
            pose.velocity_m_s,
            pose.angular_velocity_rad_s,
        )
        counts.admit()
        if not self.node.world.service.tracker_for("drone").push(sample):
            raise InputRefused("order", "older than, or jumping from, the latest pose")
        # the world the poses are in: a world-frame goal must name it, the tip in the
        # world is published in it (PX4's NED is turned into [ros2] world_frame's ENU)
        self.pose_frame = ros.world_frame if kind == "px4" else msg.header.frame_id

    def world_frame(self) -> str:
        """The world's frame id: the ROS pose input's (its samples' frame), else ``[ros2]
        world_frame`` (a hold on another pose source)."""
        return self.pose_frame or self.ros.world_frame

    def _on_goal(self, msg: Any, counts: Input) -> None:
        ros = self.ros
        goal = goal_from(msg, ros.goal_input == "pose", ros.base_frame, ros.input_world_frames)
        check_stamp(goal.t_s, time.time(), ros.stamp_future_s, ros.stamp_age_s)
        if goal.frame == "world" and msg.header.frame_id != self.world_frame():
            raise InputRefused(
                "frame",
                f"header.frame_id: {msg.header.frame_id!r} is not the world the drone's pose "
                f"is in ({self.world_frame()!r}): no transform between them is known",
            )
        counts.admit()
        view = self.node.holder.view()
        if self.armed_by is None or view.holder != self.armed_by or view.lost:
            raise InputRefused(
                "unarmed",
                "ROS goals are not armed: the operator who holds control arms them "
                "(PUT /api/ros2/goals)",
            )
        if goal.frame == "base":
            outcome = self.node.controller.set_goal(goal.point_m, goal.phi_rad or 0.0)
        else:
            outcome = self.node.controller.submit_motion(lambda: self._world_goal(goal))
        outcome.add_done_callback(self._goal_done)

    def _world_goal(self, goal: GoalIn) -> None:
        # the control thread: the running source is read where it is owned
        source = self.node.controller.state.source
        if not isinstance(source, HoldSource):
            raise MotionRefused("a world-frame goal needs a hold in the world (none running)")
        drone = source.drone_pose()
        if drone is None:
            raise MotionRefused("a world-frame goal needs the drone's pose (none yet)")
        # checked as a base-frame goal is, at the drone's latest pose
        base = Pose.from_arrays(drone[:3], drone[3:]) @ source.mount
        goal_base = base.apply_inverse(goal.point_m)
        phi = goal.phi_rad or 0.0
        if not source.gate.inside(goal_base, phi):
            raise GoalRejected(
                f"point: the world goal is at {np.round(goal_base, 4).tolist()} m in the base "
                "frame at the drone's pose: outside the workspace"
            )
        source.goal_world = goal.point_m.copy()
        if goal.phi_rad is not None and source.wrist is not None:
            source.heading = goal.phi_rad

    def _goal_done(self, outcome: Any) -> None:
        error = outcome.exception()
        if error is not None and self.goal is not None:
            self.goal.refuse(type(error).__name__, str(error)[:300])

    # the station, through the link (op ros_goals)
    def arm_goals(self, station: str, enabled: bool) -> dict[str, Any]:
        """Arm (or disarm) the goal input for ``station`` (the link's holder)."""
        if self.goal is None:
            raise ValueError("enabled: [ros2] goal_input is off in the robot node's config")
        self.armed_by = station if enabled else None
        return self.view()

    def view(self) -> dict[str, Any]:
        """The ROS side's status: the publisher, the inputs, whether goals are armed."""
        view = self.node.holder.view()
        armed = self.armed_by is not None and view.holder == self.armed_by and not view.lost
        return {
            "publisher": None if self.publisher is None else self.publisher.view(),
            "pose_input": None if self.pose is None else self.pose.view(),
            "goal_input": None if self.goal is None else self.goal.view() | {"armed": armed},
        }

    def diagnostics(self) -> dict[str, str]:
        """The inputs' figures as the diagnostics' key-values."""
        values: dict[str, str] = {}
        for label, counts in (("pose input", self.pose), ("goal input", self.goal)):
            if counts is None:
                continue
            view = counts.view()
            refused = sum(view["refused"].values())
            values[f"{label}"] = f"{view['state']} ({view['topic']})"
            values[f"{label} accepted"] = str(view["accepted"])
            dropped = view["dropped_too_fast"] + view["dropped_undecoded"]
            values[f"{label} refused"] = str(refused + dropped)
            if view["last_refusal"]:
                values[f"{label} last refusal"] = view["last_refusal"]
        if self.goal is not None:
            values["goal input armed"] = str(self.view()["goal_input"]["armed"]).lower()
        return values

    def close(self) -> None:
        if self.publisher is not None:
            self.publisher.close()
        for item in [*self._subscribers, *self._tokens]:
            with contextlib.suppress(zenoh.ZError):
                item.undeclare()

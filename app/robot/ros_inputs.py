"""ROS 2 messages the robot node takes, to pose samples and tip goals: decoded, their
frames made explicit, their stamps checked.

- The drone's pose (hold-in-world): ``nav_msgs/Odometry`` (pose in ``header.frame_id``, a
  world frame: ENU, z up; twist in ``child_frame_id``, the body: FLU, REP 103/105),
  ``geometry_msgs/PoseStamped`` (mavros' local_position/pose, vrpn: a world frame, ENU) or
  ``px4_msgs/VehicleOdometry`` (PX4: position and attitude in NED / FRD, velocity in NED
  or the body's FRD, converted by app/world/frames.py; a pose in PX4's FRD frame, whose
  heading is arbitrary, is refused).
- A tip goal: ``geometry_msgs/PoseStamped`` (the wrist angle: the pose's yaw) or
  ``PointStamped``, in the Delta's base frame or in a world frame.

Every refusal is an :class:`InputRefused` with a short ``key`` (what is counted) and a
text naming the field and the reason. Stamps are the sender's (ROS time: seconds since the
epoch where the graph's clocks are synchronised; docs/ros2.md, "Time").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.world.frames import attitude_ned_frd_to_enu_flu, frd_to_flu, ned_to_enu
from kinematics.pose import quaternion_to_matrix


class InputRefused(ValueError):
    """A message refused: ``key`` names the kind of refusal (counted), the text why."""

    def __init__(self, key: str, text: str) -> None:
        super().__init__(text)
        self.key = key


@dataclass(frozen=True)
class PoseIn:
    """The drone body's pose in the world at ``t_s`` [s]: position (3,) [m], quaternion
    (w, x, y, z) body (FLU) to world (ENU), velocity (3,) [m/s, world] and angular
    velocity (3,) [rad/s, body] when the message gives them."""

    t_s: float
    position_m: np.ndarray
    quaternion: np.ndarray
    velocity_m_s: np.ndarray | None = None
    angular_velocity_rad_s: np.ndarray | None = None


@dataclass(frozen=True)
class GoalIn:
    """A tip goal: ``frame`` base or world, the point (3,) [m], the wrist angle [rad]
    (None: a point without one)."""

    t_s: float
    frame: str
    point_m: np.ndarray
    phi_rad: float | None


def decode(store: Any, typename: str, payload: bytes) -> Any:
    """``payload`` (CDR with its header) as a ``typename`` message; InputRefused ("cdr")
    when it is not one (truncated, another type under this name)."""
    try:
        return store.deserialize_cdr(payload, typename)
    except Exception as exc:  # rosbags raises several kinds for bad bytes
        raise InputRefused("cdr", f"not a {typename} in CDR: {exc}"[:200]) from None


def stamp_s(header: Any) -> float:
    """A header's stamp [s]."""
    return float(header.stamp.sec) + float(header.stamp.nanosec) * 1e-9


def check_stamp(t_s: float, now_s: float, future_s: float, age_s: float) -> None:
    """Refuse a stamp more than ``future_s`` ahead of ``now_s`` or ``age_s`` behind it."""
    if not math.isfinite(t_s):
        raise InputRefused("stamp", "header.stamp: not a finite time")
    if t_s - now_s > future_s:
        raise InputRefused(
            "future", f"header.stamp: {t_s - now_s:.3f} s in the future (clocks in sync?)"
        )
    if now_s - t_s > age_s:
        raise InputRefused("old", f"header.stamp: {now_s - t_s:.3f} s old, more than {age_s:g} s")


def _vector(values: Any, field: str) -> np.ndarray:
    vector = np.asarray(values, dtype=np.float64)
    if vector.shape != (3,) or not np.isfinite(vector).all():
        raise InputRefused("value", f"{field}: not 3 finite numbers")
    return vector


def _xyz(point: Any, field: str) -> np.ndarray:
    return _vector([point.x, point.y, point.z], field)


def _quaternion(q: Any, field: str) -> np.ndarray:
    wxyz = np.asarray([q.w, q.x, q.y, q.z], dtype=np.float64)
    norm = float(np.linalg.norm(wxyz))
    if not np.isfinite(wxyz).all() or abs(norm - 1.0) > 1e-3:
        raise InputRefused("value", f"{field}: not a unit quaternion (norm {norm:.4g})")
    return wxyz / norm


def _world_frame(frame: str, world_frames: tuple[str, ...], field: str) -> None:
    if frame not in world_frames:
        raise InputRefused(
            "frame",
            f"{field}: {frame!r} is not a world frame this input takes "
            f"({', '.join(world_frames)}; [ros2] input_world_frames)",
        )


def pose_from_odometry(msg: Any, world_frames: tuple[str, ...], body_frame: str) -> PoseIn:
    """nav_msgs/Odometry: the pose in a world frame, the twist in the body ``body_frame``
    (FLU, its ``child_frame_id``), turned into the world for the velocity."""
    _world_frame(msg.header.frame_id, world_frames, "header.frame_id")
    if msg.child_frame_id != body_frame:
        raise InputRefused(
            "frame",
            f"child_frame_id: {msg.child_frame_id!r} is not the drone's body "
            f"({body_frame!r}, [ros2] drone_frame): the twist would be in another frame",
        )
    pose = msg.pose.pose
    q = _quaternion(pose.orientation, "pose.pose.orientation")
    twist = msg.twist.twist
    v_body = _xyz(twist.linear, "twist.twist.linear")
    omega = _xyz(twist.angular, "twist.twist.angular")
    velocity = quaternion_to_matrix(q) @ v_body
    return PoseIn(
        stamp_s(msg.header), _xyz(pose.position, "pose.pose.position"), q, velocity, omega
    )


def pose_from_pose_stamped(msg: Any, world_frames: tuple[str, ...]) -> PoseIn:
    """geometry_msgs/PoseStamped in a world frame (no velocity: the tracker differences)."""
    _world_frame(msg.header.frame_id, world_frames, "header.frame_id")
    pose = msg.pose
    return PoseIn(
        stamp_s(msg.header),
        _xyz(pose.position, "pose.position"),
        _quaternion(pose.orientation, "pose.orientation"),
    )


def pose_from_px4(msg: Any) -> PoseIn:
    """px4_msgs/VehicleOdometry: ``timestamp`` [us], NED position and FRD-to-NED attitude,
    velocity in NED or the body's FRD; to ENU / FLU."""
    if msg.pose_frame != msg.POSE_FRAME_NED:
        raise InputRefused(
            "frame",
            f"pose_frame: {msg.pose_frame} (1 is NED; FRD's heading is arbitrary, "
            "and UNKNOWN cannot be used)",
        )
    position = ned_to_enu(_vector(msg.position, "position"))
    q = np.asarray(msg.q, dtype=np.float64)
    if q.shape != (4,) or not np.isfinite(q).all() or abs(np.linalg.norm(q) - 1.0) > 1e-3:
        raise InputRefused("value", "q: not a unit quaternion")
    attitude = attitude_ned_frd_to_enu_flu(q / np.linalg.norm(q))
    velocity = None
    v = np.asarray(msg.velocity, dtype=np.float64)
    if np.isfinite(v).all():  # PX4 sends NaN for what it does not know
        if msg.velocity_frame == msg.VELOCITY_FRAME_NED:
            velocity = ned_to_enu(v)
        elif msg.velocity_frame == msg.VELOCITY_FRAME_BODY_FRD:
            velocity = quaternion_to_matrix(attitude) @ frd_to_flu(v)
    w = np.asarray(msg.angular_velocity, dtype=np.float64)
    omega = frd_to_flu(w) if np.isfinite(w).all() else None
    return PoseIn(float(msg.timestamp) * 1e-6, position, attitude, velocity, omega)


def goal_from(msg: Any, with_pose: bool, base_frame: str, world_frames: tuple[str, ...]) -> GoalIn:
    """A tip goal from a PoseStamped (``with_pose``: the wrist angle is its yaw) or a
    PointStamped, in ``base_frame`` or one of ``world_frames``."""
    frame_id = msg.header.frame_id
    if frame_id == base_frame:
        frame = "base"
    elif frame_id in world_frames:
        frame = "world"
    else:
        raise InputRefused(
            "frame",
            f"header.frame_id: {frame_id!r} is neither the base frame ({base_frame!r}) "
            f"nor a world frame ({', '.join(world_frames)})",
        )
    phi = None
    if with_pose:
        point = _xyz(msg.pose.position, "pose.position")
        w, x, y, z = _quaternion(msg.pose.orientation, "pose.orientation")
        if abs(x) > 1e-6 or abs(y) > 1e-6:
            raise InputRefused(
                "value", "pose.orientation: a Delta's tool only turns about z (roll, pitch 0)"
            )
        phi = 2.0 * math.atan2(z, w)
        phi = math.remainder(phi, 2 * math.pi)
    else:
        point = _xyz(msg.point, "point")
    return GoalIn(stamp_s(msg.header), frame, point, phi)

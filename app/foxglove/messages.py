"""The robot as Foxglove messages: a snapshot of the loop to the channels' messages.

Pure functions of a :class:`~app.control.state.Snapshot` (and the settings), so the live
server (server.py) only times and sends them. The frames are the ROS 2 topics' own
(``[ros2]`` frame and joint names, app/ros2/messages.py), so Foxglove and a ROS graph
agree: the drone's body carries the Delta's base at the mount (``[world]``), the platform
translates in the base frame (a Delta's platform keeps the base's orientation), the tool
tip is the tool offset turned by the wrist angle about z, and the goal is the tip's goal
in the base frame. Positions are in metres and radians; the JSON channels carry
``null`` where the loop knows no value (NaN: no read yet, no setpoint), since JSON has no
NaN.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from foxglove.messages import (
    Event,
    FrameTransform,
    FrameTransforms,
    JointState,
    JointStates,
    KeyValuePair,
    Log,
    LogLevel,
    Quaternion,
    Timestamp,
    Vector3,
)

from app.config import Settings
from app.control.loop_health import classify
from app.control.state import Fault, Snapshot

# the channels (topic -> what): the layout (layout.py) and docs/foxglove.md name them
TF = "/tf"  # foxglove.FrameTransforms
JOINT_STATES = "/joint_states"  # foxglove.JointStates
TRACKING = "/deltadash/tracking"  # JSON: the tip's tracking error and its points
LOOP = "/deltadash/loop"  # JSON: the loop's health
LOG = "/deltadash/log"  # foxglove.Log: faults, e-stop, warnings, runs
RUNS = "/deltadash/runs"  # foxglove.Event: a run's start and end
TOPICS = (TF, JOINT_STATES, TRACKING, LOOP, LOG, RUNS)
LOG_NAME = "deltadash"  # the Log messages' ``name`` (the source the Log panel shows)
HEALTH_LEVELS = {"unknown": -1, "green": 0, "amber": 1, "red": 2}

_XYZ = {
    "type": ["object", "null"],
    "properties": {axis: {"type": ["number", "null"]} for axis in "xyz"},
}
_NUMBER = {"type": ["number", "null"]}
TRACKING_SCHEMA: dict[str, Any] = {
    "title": "deltadash.Tracking",
    "description": "The tool tip's tracking error (commanded minus measured, null without a "
    "setpoint) and its points, in the base frame [m]",
    "type": "object",
    "properties": {
        "tick": {"type": "integer"},
        "time_s": {"type": "number", "description": "the loop's time [s]"},
        "mode": {"type": "string"},
        "error_m": _XYZ,
        "error_mm": _XYZ,
        "error_norm_mm": _NUMBER,
        "measured_m": _XYZ,
        "commanded_m": _XYZ,
        "goal_m": _XYZ,
        "platform_m": _XYZ,
        "phi_rad": _NUMBER,
        "contact_force_n": {
            **_XYZ,
            "description": "the tip's contact force estimate, the force it applies [N] "
            "(docs/contact.md); null while not valid",
        },
        "contact_std_n": _XYZ,
        "contact_valid": {"type": "boolean"},
    },
}
LOOP_SCHEMA: dict[str, Any] = {
    "title": "deltadash.LoopHealth",
    "description": "The control loop's timing over its last 10 s (rates, lateness, overruns) "
    "and its state",
    "type": "object",
    "properties": {
        "tick": {"type": "integer"},
        "rate_hz": _NUMBER,
        "target_hz": _NUMBER,
        "lateness_ms": _NUMBER,
        "lateness_p50_ms": _NUMBER,
        "lateness_p99_ms": _NUMBER,
        "worst_ms": _NUMBER,
        "longest_gap_ms": _NUMBER,
        "overruns_10s": {"type": "integer"},
        "overruns_total": {"type": "integer"},
        "feedback_age_ms": _NUMBER,
        "missed_reads": {"type": "integer"},
        "health": {"type": "string", "enum": list(HEALTH_LEVELS)},
        "health_level": {"type": "integer", "description": "-1 unknown, 0 green, 1 amber, 2 red"},
        "mode": {"type": "string"},
        "torque": {"type": "boolean"},
        "estopped": {"type": "boolean"},
        "faults": {"type": "integer"},
    },
}


def number(value: Any) -> float | None:
    """``value`` as a float, None where it is not finite (JSON has no NaN)."""
    value = float(value)
    return value if math.isfinite(value) else None


def xyz(values: Sequence[float] | np.ndarray) -> dict[str, float | None] | None:
    """A point as ``{"x", "y", "z"}`` (null where unknown); None when all three are."""
    x, y, z = (number(v) for v in values)
    return None if x is None and y is None and z is None else {"x": x, "y": y, "z": z}


def timestamp(ns: int) -> Timestamp:
    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def _turn(phi_rad: float) -> Quaternion:
    """The rotation by ``phi_rad`` about z (identity for a non-finite angle)."""
    phi = phi_rad if math.isfinite(phi_rad) else 0.0
    return Quaternion(x=0.0, y=0.0, z=math.sin(phi / 2), w=math.cos(phi / 2))


def _vector(values: Sequence[float] | np.ndarray) -> Vector3:
    x, y, z = (float(v) for v in values)
    return Vector3(x=x, y=y, z=z)


class Builder:
    """The messages of one configuration: frame and joint names, the tool offset, the
    mount and whether a wrist is fitted (``settings``: the station's, with the robot
    node's sections)."""

    def __init__(self, settings: Settings) -> None:
        ros, world = settings.ros2, settings.world
        self.base, self.platform, self.tip = ros.base_frame, ros.platform_frame, ros.tip_frame
        self.drone, self.goal = ros.drone_frame, settings.foxglove.goal_frame
        self.joint_names = list(ros.joint_names)
        self.wrist_name = ros.wrist_joint_name if settings.wrist.enabled else None
        self.tool_offset = np.asarray(settings.tool.offset_m, dtype=float)
        w, x, y, z = (float(v) for v in world.mount_quaternion)
        self.mount = (
            _vector(world.mount_position_m),
            Quaternion(x=x, y=y, z=z, w=w),
        )

    def _transform(
        self, stamp: Timestamp, parent: str, child: str, xyz_m: Any, rotation: Quaternion
    ) -> FrameTransform:
        return FrameTransform(
            timestamp=stamp,
            parent_frame_id=parent,
            child_frame_id=child,
            translation=_vector(xyz_m),
            rotation=rotation,
        )

    def transforms(self, snap: Snapshot, stamp_ns: int) -> FrameTransforms:
        """The drone's body -> base (the mount), base -> platform (measured) -> tip (the
        tool offset turned by the wrist), and base -> goal (the tip's goal, turned by its
        wrist angle); a frame whose position is unknown (no read yet, no goal) is left out."""
        stamp = timestamp(stamp_ns)
        translation, rotation = self.mount
        out = [
            FrameTransform(
                timestamp=stamp,
                parent_frame_id=self.drone,
                child_frame_id=self.base,
                translation=translation,
                rotation=rotation,
            )
        ]
        platform = np.asarray(snap.platform_measured_m, dtype=float)
        if np.isfinite(platform).all():
            out.append(self._transform(stamp, self.base, self.platform, platform, _turn(0.0)))
            # the platform frame keeps the base's axes: the tip is at Rz(phi) d in it
            # (kinematics/tool.py), and its own frame is turned by phi
            phi = snap.tool_phi_rad if math.isfinite(snap.tool_phi_rad) else 0.0
            c, s = math.cos(phi), math.sin(phi)
            x, y, z = self.tool_offset
            offset = (c * x - s * y, s * x + c * y, z)
            out.append(self._transform(stamp, self.platform, self.tip, offset, _turn(phi)))
        goal = np.asarray(snap.goal_m, dtype=float)
        if np.isfinite(goal).all():
            finite = [a for a in (snap.phi_goal_rad, snap.phi_commanded_rad) if math.isfinite(a)]
            phi = finite[0] if finite else snap.phi_rad
            out.append(self._transform(stamp, self.base, self.goal, goal, _turn(phi)))
        return FrameTransforms(transforms=out)

    def joint_states(self, snap: Snapshot, stamp_ns: int) -> JointStates:
        """The joints as read [rad, rad/s] (the wrist as a fourth when fitted); a value
        not known (no read yet) is left unset."""
        position = np.asarray(snap.joints_measured_rad, dtype=float)
        velocity = np.asarray(snap.velocity_rad_s, dtype=float)
        joints = [
            JointState(name=name, position=number(p), velocity=number(v))
            for name, p, v in zip(self.joint_names, position, velocity, strict=True)
        ]
        if self.wrist_name is not None:
            joints.append(JointState(name=self.wrist_name, position=number(snap.phi_measured_rad)))
        return JointStates(timestamp=timestamp(stamp_ns), joints=joints)


def tracking(snap: Snapshot) -> dict[str, Any]:
    """The tip's tracking error as the operator is shown it (commanded minus measured,
    null without a setpoint: Snapshot.shown_error_m) [m], its norm [mm], and the points."""
    error = np.asarray(snap.shown_error_m, dtype=float)
    norm = float(np.linalg.norm(error))
    return {
        "tick": snap.tick,
        "time_s": snap.time_s,
        "mode": snap.mode,
        "error_m": xyz(error),
        "error_mm": xyz(error * 1e3),
        "error_norm_mm": number(norm * 1e3),
        "measured_m": xyz(snap.point_measured_m),
        "commanded_m": xyz(snap.point_commanded_m),
        "goal_m": xyz(snap.goal_m),
        "platform_m": xyz(snap.platform_measured_m),
        "phi_rad": number(snap.tool_phi_rad),
        "contact_force_n": xyz(snap.contact.force_n) if snap.contact.valid else None,
        "contact_std_n": xyz(snap.contact.std_n) if snap.contact.valid else None,
        "contact_valid": snap.contact.valid,
    }


def loop_health(snap: Snapshot) -> dict[str, Any]:
    """The loop's timing over its last 10 s and its health light (app/control/
    loop_health.py: the dashboard's), with the tick's own lateness and the robot's state."""
    window, total = snap.loop_window, snap.loop_total
    health = classify(window).level
    return {
        "tick": snap.tick,
        "rate_hz": number(window.measured_hz),
        "target_hz": number(total.target_hz),
        "lateness_ms": number(snap.lateness_ms),
        "lateness_p50_ms": number(window.jitter_p50_ms),
        "lateness_p99_ms": number(window.jitter_p99_ms),
        "worst_ms": number(window.worst_ms),
        "longest_gap_ms": number(window.longest_gap_ms),
        "overruns_10s": int(window.overruns),
        "overruns_total": int(total.overruns),
        "feedback_age_ms": number(snap.feedback_age_ms),
        "missed_reads": int(snap.missed_reads),
        "health": health,
        "health_level": HEALTH_LEVELS.get(health, -1),
        "mode": snap.mode,
        "torque": bool(snap.torque),
        "estopped": bool(snap.estopped),
        "faults": len(snap.faults),
    }


def log(stamp_ns: int, level: LogLevel, message: str, file: str = "") -> Log:
    return Log(
        timestamp=timestamp(stamp_ns), level=level, message=message, name=LOG_NAME, file=file
    )


def fault_text(fault: Fault) -> str:
    """A fault as one line: its reason, where it came from, how often it was seen."""
    where = f"{fault.source}" + (f", servo {fault.servo_id}" if fault.servo_id is not None else "")
    again = f", seen {fault.count} times" if fault.count > 1 else ""
    return f"fault: {fault.reason} ({where}{again})"


class StateLog:
    """What changed between two snapshots that an operator should read in the Log panel:
    a new fault (or one seen again), the faults cleared, e-stop pressed and released, a
    warning raised; ``changes(snap)`` gives them as (level, text) since the last call."""

    def __init__(self) -> None:
        self._faults: dict[tuple, int] = {}
        self._estopped: bool | None = None
        self._warning: str | None = None

    def changes(self, snap: Snapshot) -> list[tuple[LogLevel, str]]:
        out: list[tuple[LogLevel, str]] = []
        if self._estopped is not None and snap.estopped != self._estopped:
            out.append(
                (LogLevel.Error, "e-stop") if snap.estopped else (LogLevel.Info, "e-stop reset")
            )
        self._estopped = snap.estopped
        seen = {fault.cause: fault.count for fault in snap.faults}
        for fault in snap.faults:
            if self._faults.get(fault.cause, 0) < fault.count:
                out.append((LogLevel.Error, fault_text(fault)))
        if self._faults and not seen:
            out.append((LogLevel.Info, "faults cleared"))
        self._faults = seen
        if snap.warning and snap.warning != self._warning:
            out.append((LogLevel.Warning, f"warning: {snap.warning}"))
        self._warning = snap.warning
        return out


def _pairs(items: Iterable[tuple[str, Any]]) -> list[KeyValuePair]:
    return [KeyValuePair(key=k, value=str(v)) for k, v in items if v is not None]


def run_event(run: Any, ended: bool, now_ns: int) -> Event:
    """A run as an event: at its start the instant it started, at its end the span from
    start to end (``now_ns`` while its record has no end time yet), with its id, kind
    and (at the end) how it ended and why."""
    start = timestamp(round(run.started_at * 1e9))
    if not ended:
        end = start
    else:
        end = timestamp(round(run.ended_at * 1e9) if run.ended_at else now_ns)
    items: list[tuple[str, Any]] = [
        ("event", "run end" if ended else "run start"),
        ("run_id", run.run_id),
        ("kind", run.kind),
    ]
    if ended:
        items += [("state", run.state), ("reason", run.reason), ("samples", run.samples)]
    return Event(start_time=start, end_time=end, metadata=_pairs(items))


def run_text(run: Any, ended: bool) -> tuple[LogLevel, str]:
    """A run's start or end as a Log line (an aborted or interrupted run: a warning)."""
    if not ended:
        return LogLevel.Info, f"run {run.run_id} ({run.kind}) started"
    why = f": {run.reason}" if run.reason else ""
    level = LogLevel.Info if run.state == "done" else LogLevel.Warning
    return level, f"run {run.run_id} ({run.kind}) {run.state}{why}"

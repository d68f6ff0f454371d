"""Pose inputs from outside: a UDP JSON stream and a MAVLink ODOMETRY listener.

UDP: one JSON object per datagram, the same as POST /api/mav/pose:
``{"t": 12.34, "position": [x, y, z], "quaternion": [w, x, y, z], "velocity": [vx, vy, vz]}``
(world frame z up [m], body to world, velocity optional). An optional ``"body"`` says whose
pose it is: ``"drone"`` (the default: the robot's base, for hold-in-world) or
``"platform"`` (a motion-capture marker on the platform: the measurement of a calibration
run with ``measurement: "pose-input"``). MAVLink: ODOMETRY messages from a
PX4/ArduPilot autopilot via pymavlink, converted from NED/FRD (app/world/frames.py).
Each listener is a daemon thread that pushes vetted samples into a PoseTracker.
"""

from __future__ import annotations

import json
import logging
import socket
import threading
from typing import Any

import numpy as np

from app.world.frames import attitude_ned_frd_to_enu_flu, frd_to_flu, ned_to_enu
from app.world.poses import PoseTracker, make_sample
from kinematics import PoseError

log = logging.getLogger(__name__)


BODIES = ("drone", "platform")  # whose pose a sample is: the base's, or the platform's


def body_of(data: dict[str, Any]) -> str:
    """The ``body`` field of a pose object ("drone" when absent); PoseError for another
    value, or for a message that is not a JSON object."""
    if not isinstance(data, dict):
        raise PoseError(f"a pose is a JSON object, got {type(data).__name__}")
    body = data.get("body", "drone")
    if body not in BODIES:
        raise PoseError(f"body: {body!r} is not one of {', '.join(map(repr, BODIES))}")
    return body


def sample_from_json(data: dict[str, Any]):
    """A PoseSample from the documented JSON; PoseError or KeyError names what is wrong."""
    missing = [key for key in ("t", "position", "quaternion") if key not in data]
    if missing:
        raise PoseError(f"missing field(s): {', '.join(missing)}")
    return make_sample(
        data["t"],
        data["position"],
        data["quaternion"],
        data.get("velocity"),
        data.get("angular_velocity"),
    )


class UdpPoseListener:
    """Receives JSON pose datagrams on ``port`` (127.0.0.1 unless ``host`` says otherwise):
    the drone's into ``tracker``, the platform marker's (``"body": "platform"``) into
    ``platform`` (counted as errors when there is none)."""

    def __init__(
        self,
        tracker: PoseTracker,
        port: int,
        host: str = "127.0.0.1",
        platform: PoseTracker | None = None,
    ) -> None:
        self.tracker, self.platform = tracker, platform
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.socket.bind((host, port))
        self.socket.settimeout(0.2)
        self.port = self.socket.getsockname()[1]
        self.errors = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pose-udp", daemon=True)

    def start(self) -> UdpPoseListener:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.socket.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                payload, _ = self.socket.recvfrom(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            try:
                data = json.loads(payload)
                tracker = self.tracker if body_of(data) == "drone" else self.platform
                if tracker is None:
                    raise PoseError("body: 'platform' poses are not taken here")
                tracker.push(sample_from_json(data))
            except (ValueError, KeyError, TypeError) as exc:
                self.errors += 1
                log.debug("bad pose datagram: %s", exc)


# MAVLink MAV_FRAME values (common.xml) that ODOMETRY may name
MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_BODY_NED = 8
MAV_FRAME_BODY_FRD = 12
MAV_FRAME_LOCAL_FRD = 20
# the pose's frame_id: an earth-fixed local frame, z down (NED, or FRD: x along some
# fixed heading); either becomes the z-up world the same way (x <-> y, z -> -z)
POSE_FRAMES = {
    MAV_FRAME_LOCAL_NED: "MAV_FRAME_LOCAL_NED",
    MAV_FRAME_LOCAL_FRD: "MAV_FRAME_LOCAL_FRD",
}
# the velocity's child_frame_id in the body: FRD. MAV_FRAME_BODY_NED is, for velocities,
# the same as MAV_FRAME_BODY_FRD (common.xml).
BODY_VELOCITY_FRAMES = {
    MAV_FRAME_BODY_FRD: "MAV_FRAME_BODY_FRD",
    MAV_FRAME_BODY_NED: "MAV_FRAME_BODY_NED",
}


class FrameRefused(PoseError):
    """An ODOMETRY frame this input does not take. ``field`` is "frame_id" or
    "child_frame_id"; ``key`` names field and frame ("child_frame_id MAV_FRAME_LOCAL_ENU"),
    the key it is counted under in the pose input's status (``refused_frames``)."""

    def __init__(self, field: str, frame: int, reason: str) -> None:
        self.field, self.frame = field, frame
        self.key = f"{field} {_frame_name(frame)}"
        super().__init__(f"ODOMETRY {self.key}: {reason}")


def _frame_name(frame: int) -> str:
    try:
        from pymavlink.dialects.v20 import common

        entry = common.enums["MAV_FRAME"].get(int(frame))
    except (ImportError, KeyError, TypeError, ValueError):
        entry = None
    return entry.name if entry is not None else f"MAV_FRAME {frame}"


def odometry_velocity_enu(
    child_frame_id: int, frame_id: int, velocity: np.ndarray, rotation: np.ndarray
) -> np.ndarray:
    """An ODOMETRY velocity (3,) [m/s] in ``child_frame_id`` as a world (ENU, z up) vector.

    Body frames (MAV_FRAME_BODY_FRD, MAV_FRAME_BODY_NED: FRD for velocities) go FRD -> FLU,
    then through ``rotation`` (3, 3), the body (FLU) to world (ENU) attitude. An earth frame
    (MAV_FRAME_LOCAL_NED, MAV_FRAME_LOCAL_FRD) goes NED -> ENU (x <-> y, z -> -z) and must
    be the pose's ``frame_id``: two different earth frames have an unknown heading between
    them. Raises FrameRefused (field "child_frame_id") for any other frame.
    """
    if child_frame_id in BODY_VELOCITY_FRAMES:
        return rotation @ frd_to_flu(velocity)
    if child_frame_id in POSE_FRAMES:
        if child_frame_id != frame_id:
            raise FrameRefused(
                "child_frame_id",
                child_frame_id,
                f"an earth-frame velocity must be in the pose's frame_id {_frame_name(frame_id)}",
            )
        return ned_to_enu(velocity)
    raise FrameRefused(
        "child_frame_id",
        child_frame_id,
        "the velocity is taken in MAV_FRAME_BODY_FRD, MAV_FRAME_BODY_NED, or the pose's "
        "MAV_FRAME_LOCAL_NED / MAV_FRAME_LOCAL_FRD",
    )


def sample_from_odometry(msg: Any):
    """A PoseSample in the project's frames from a MAVLink ODOMETRY message.

    Pose: ``frame_id`` MAV_FRAME_LOCAL_NED or MAV_FRAME_LOCAL_FRD (z down, earth-fixed)
    -> world ENU (z up); attitude FRD body -> NED becomes FLU body -> ENU, (w, x, y, z).
    Velocity [m/s]: in ``child_frame_id`` (see `odometry_velocity_enu`), returned in the
    world. Angular velocity [rad/s]: body FRD -> FLU.

    Raises FrameRefused (a PoseError naming the field and frame) for a frame not taken;
    PoseError / ValueError for bad values.
    """
    if msg.frame_id not in POSE_FRAMES:
        raise FrameRefused(
            "frame_id",
            msg.frame_id,
            "the pose is taken in MAV_FRAME_LOCAL_NED or MAV_FRAME_LOCAL_FRD",
        )
    position = ned_to_enu(np.array([msg.x, msg.y, msg.z]))
    quaternion = attitude_ned_frd_to_enu_flu(np.asarray(msg.q, dtype=np.float64))
    body_velocity = np.array([msg.vx, msg.vy, msg.vz], dtype=np.float64)
    omega = frd_to_flu(np.array([msg.rollspeed, msg.pitchspeed, msg.yawspeed]))
    sample = make_sample(msg.time_usec * 1e-6, position, quaternion, None, omega)
    world_velocity = odometry_velocity_enu(
        msg.child_frame_id, msg.frame_id, body_velocity, sample.pose.rotation
    )
    return make_sample(sample.t_s, position, quaternion, world_velocity, omega)


def push_odometry(tracker: PoseTracker, msg: Any) -> bool:
    """Decode ``msg`` (`sample_from_odometry`) and push it into ``tracker``: the push's
    result. A refused frame is counted in ``tracker`` (its status's ``refused_frames``)
    and re-raised, like every other error."""
    try:
        sample = sample_from_odometry(msg)
    except FrameRefused as exc:
        tracker.refuse(exc.key)
        raise
    return tracker.push(sample)


class MavlinkPoseListener:
    """Reads ODOMETRY from ``url`` (pymavlink connection string) into ``tracker``."""

    def __init__(self, tracker: PoseTracker, url: str) -> None:
        from pymavlink import mavutil

        self.tracker = tracker
        self.connection = mavutil.mavlink_connection(url, dialect="common")
        self.errors = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pose-mavlink", daemon=True)

    def start(self) -> MavlinkPoseListener:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.connection.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.connection.recv_match(type="ODOMETRY", blocking=True, timeout=0.2)
            if msg is None:
                continue
            try:
                push_odometry(self.tracker, msg)
            except (ValueError, PoseError) as exc:
                self.errors += 1
                log.debug("bad ODOMETRY: %s", exc)

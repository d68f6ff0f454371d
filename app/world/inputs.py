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

import contextlib
import json
import logging
import socket
import threading
from typing import Any

import numpy as np

from app.control.authority import token_ok
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
    """A PoseSample from the documented JSON; PoseError or KeyError names what is wrong.
    ``source`` (set by the receiving input, never by a client: the HTTP route forbids it,
    the WebSocket route and the UDP listener overwrite it) names the input; "http" when
    absent."""
    missing = [key for key in ("t", "position", "quaternion") if key not in data]
    if missing:
        raise PoseError(f"missing field(s): {', '.join(missing)}")
    try:
        return make_sample(
            data["t"],
            data["position"],
            data["quaternion"],
            data.get("velocity"),
            data.get("angular_velocity"),
            source=data.get("source", "http"),
        )
    except OverflowError:  # an integer too large for a float (e.g. 400 digits)
        raise PoseError("a number is too large (beyond a 64-bit float)") from None


def parse_pose(payload: str | bytes) -> dict[str, Any]:
    """The JSON object of one datagram or WebSocket frame; PoseError for anything else (not
    UTF-8, not JSON, nested too deep, not an object), naming the reason."""
    try:
        data = json.loads(payload)
    except RecursionError:
        raise PoseError("not a pose: JSON nested too deep") from None
    except ValueError as exc:  # UnicodeDecodeError and JSONDecodeError included
        raise PoseError(f"not JSON: {exc}") from None
    body_of(data)  # an object, with a known body
    return data


class PoseInput:
    """What every listener thread shares: counters, the last error, whether it is alive,
    and a restart. ``rule`` says what it takes: "open" (no token is set), "token" (a UDP
    datagram carries the server token), "trusted" (configured as a trusted local bridge),
    "signed" (MAVLink2 signing with the configured key) or "refused" (a token is set and
    the input is neither trusted nor signed: every message is refused and counted).

    A listener thread survives every message: a bad one is counted in ``errors`` (refused
    ones in ``refused``) and named in ``last_error``. A thread that ends anyway (its socket
    closed under it, a bug) leaves its reason in ``last_error`` and ``alive`` false, until
    ``restart``."""

    name = "input"
    thread_name = "pose-input"

    def __init__(self, rule: str) -> None:
        self.rule = rule
        self.accepted = 0  # samples the tracker kept
        self.errors = 0  # messages refused as malformed (and, for UDP, refused tokens)
        self.refused = 0  # messages refused by the authority rule (no/wrong token, unsigned)
        self.restarts = 0
        self.last_error: str | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = self._new_thread()

    def _new_thread(self) -> threading.Thread:
        return threading.Thread(target=self._guarded, name=self.thread_name, daemon=True)

    def start(self):
        self._thread.start()
        return self

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def restart(self) -> bool:
        """Start the thread afresh (with a new socket or connection) when it has died;
        False when it was alive (nothing done). Raises OSError when the socket cannot be
        opened again (the port taken meanwhile)."""
        with self._lock:
            if self._thread.is_alive() or self._stop.is_set():
                return False
            self._reopen()
            self._thread = self._new_thread()
            self.restarts += 1
            self._thread.start()
            return True

    def stop(self) -> None:
        self._stop.set()
        if self._thread.ident is not None:
            self._thread.join(timeout=2.0)
        self._close()

    def status(self) -> dict[str, Any]:
        """name, enabled (True), alive, rule, accepted, errors, refused, restarts,
        last_error (text or None)."""
        return {
            "name": self.name,
            "enabled": True,
            "alive": self.alive,
            "rule": self.rule,
            "accepted": self.accepted,
            "errors": self.errors,
            "refused": self.refused,
            "restarts": self.restarts,
            "last_error": self.last_error,
        }

    def _error(self, text: str, refused: bool = False) -> None:
        if refused:
            self.refused += 1
        else:
            self.errors += 1
        self.last_error = text
        log.debug("%s: %s", self.name, text)

    def _guarded(self) -> None:
        try:
            self._run()
        except Exception as exc:  # a bug or a dead socket: recorded, visible in the status
            self.last_error = f"input stopped: {type(exc).__name__}: {exc}"
            log.exception("pose input %s stopped", self.name)

    def _handle(self, handler, *args) -> None:
        """``handler(*args)``, its PoseError (and any other exception) counted and named:
        no message ends the thread."""
        try:
            handler(*args)
        except (PoseError, ValueError, KeyError, TypeError) as exc:
            self._error(str(exc) if isinstance(exc, PoseError) else f"{type(exc).__name__}: {exc}")
        except Exception as exc:  # not foreseen: still one message's error, not the thread's
            self._error(f"{type(exc).__name__}: {exc}")
            log.warning("pose input %s: unforeseen error in a message", self.name, exc_info=True)

    def _run(self) -> None:  # pragma: no cover - each listener has its own
        raise NotImplementedError

    def _reopen(self) -> None:  # pragma: no cover
        raise NotImplementedError

    def _close(self) -> None:  # pragma: no cover
        raise NotImplementedError


class UdpPoseListener(PoseInput):
    """Receives JSON pose datagrams on ``port`` (127.0.0.1 unless ``host`` says otherwise):
    the drone's into ``tracker``, the platform marker's (``"body": "platform"``) into
    ``platform`` (counted as errors when there is none).

    ``token``: the server token; when set, each datagram carries it as ``"token"``
    (compared in constant time), or it is refused and counted in ``refused``, unless
    ``trusted`` (a trusted local bridge: ``[world] udp_trusted``). Raises OSError when the
    port cannot be bound."""

    name = "udp"
    thread_name = "pose-udp"

    def __init__(
        self,
        tracker: PoseTracker,
        port: int,
        host: str = "127.0.0.1",
        platform: PoseTracker | None = None,
        token: str | None = None,
        trusted: bool = False,
    ) -> None:
        self.tracker, self.platform = tracker, platform
        self.host, self.token = host, token
        rule = "open" if token is None else ("trusted" if trusted else "token")
        self.port = port
        self._bind()
        super().__init__(rule)

    def _bind(self) -> None:
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.socket.bind((self.host, self.port))
        except OSError:
            self.socket.close()
            raise
        self.socket.settimeout(0.2)
        self.port = self.socket.getsockname()[1]

    def _reopen(self) -> None:
        self.socket.close()
        self._bind()

    def _close(self) -> None:
        self.socket.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                payload, _ = self.socket.recvfrom(65536)
            except TimeoutError:
                continue
            except OSError as exc:
                if not self._stop.is_set():
                    self.last_error = f"input stopped: socket error: {exc}"
                return
            self._handle(self._datagram, payload)

    def _datagram(self, payload: bytes) -> None:
        data = parse_pose(payload)
        if self.rule == "token":
            supplied = data.get("token")
            if not isinstance(supplied, str) or not token_ok(self.token, supplied):
                self._error("token: missing or wrong (a token is set)", refused=True)
                return
        tracker = self.tracker if body_of(data) == "drone" else self.platform
        if tracker is None:
            raise PoseError("body: 'platform' poses are not taken here")
        if tracker.push(sample_from_json({**data, "source": "udp"})):
            self.accepted += 1


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
    return make_sample(sample.t_s, position, quaternion, world_velocity, omega, source="mavlink")


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


class MavlinkPoseListener(PoseInput):
    """Reads ODOMETRY from ``url`` (pymavlink connection string) into ``tracker``.

    ``signing_key`` (32 bytes): MAVLink2 signing; unsigned or wrongly signed messages are
    refused and counted in ``refused`` (rule "signed"). Without a key, a set ``token``
    refuses every message (rule "refused") unless ``trusted`` (rule "trusted"); with no
    token the input is "open"."""

    name = "mavlink"
    thread_name = "pose-mavlink"

    def __init__(
        self,
        tracker: PoseTracker,
        url: str,
        token: str | None = None,
        trusted: bool = False,
        signing_key: bytes | None = None,
    ) -> None:
        self.tracker, self.url, self.signing_key = tracker, url, signing_key
        if signing_key is not None:
            rule = "signed"
        else:
            rule = "open" if token is None else ("trusted" if trusted else "refused")
        super().__init__(rule)
        self._connect()

    def _connect(self) -> None:
        from pymavlink import mavutil

        self.connection = mavutil.mavlink_connection(self.url, dialect="common")
        if self.signing_key is not None:
            self.connection.setup_signing(
                self.signing_key, sign_outgoing=False, allow_unsigned_callback=self._unsigned
            )

    def _unsigned(self, _mav: Any, _msg_id: int) -> bool:
        """pymavlink's callback for an unsigned (or wrongly signed) message: refused."""
        self._error("signature: unsigned or wrongly signed MAVLink message", refused=True)
        return False

    def _reopen(self) -> None:
        self._close()
        self._connect()

    def _close(self) -> None:
        with contextlib.suppress(OSError):
            self.connection.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.connection.recv_match(type="ODOMETRY", blocking=True, timeout=0.2)
            if msg is None:
                continue
            if self.rule == "refused":
                self._error(
                    "refused: a token is set and MAVLink is neither signed nor trusted",
                    refused=True,
                )
                continue
            self._handle(self._odometry, msg)

    def _odometry(self, msg: Any) -> None:
        try:
            pushed = push_odometry(self.tracker, msg)
        except ValueError as exc:
            raise PoseError(str(exc)) from None
        if pushed:
            self.accepted += 1

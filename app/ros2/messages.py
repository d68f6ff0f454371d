"""The robot as ROS 2 messages: a snapshot of the loop to standard types, CDR-encoded.

Types and their CDR come from ``rosbags`` (its type store for the configured distribution:
the same definitions, and the RIHS01 type hashes, a ROS 2 graph uses). Frames follow REP
103/105: the Delta's base frame is the loop's own (z up, towards the drone; x towards leg
1), the platform translates in it (a Delta's platform keeps the base's orientation), the
tool tip is the platform's tool offset turned by the wrist angle about z, and the drone's
body (FLU) carries the base at the configured mount (``[world] mount_position_m``,
``mount_quaternion``). Stamps are the robot node's wall clock (``time.time()``, the ROS
graph's clock where it is synchronised: docs/ros2.md, "Time").
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from app.config import Settings
from app.control.loop_health import classify
from app.control.state import Snapshot
from kinematics import Pose

STORES = {"jazzy": Stores.ROS2_JAZZY, "humble": Stores.ROS2_HUMBLE}
JOINT_STATE = "sensor_msgs/msg/JointState"
TF = "tf2_msgs/msg/TFMessage"
POSE = "geometry_msgs/msg/PoseStamped"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
WRENCH = "geometry_msgs/msg/WrenchStamped"


ODOMETRY = "nav_msgs/msg/Odometry"
POINT = "geometry_msgs/msg/PointStamped"
PX4_ODOMETRY = "px4_msgs/msg/VehicleOdometry"
# px4_msgs/msg/VehicleOdometry as PX4 v1.14 to v1.16 define it (PX4-Autopilot msg/); its
# constants (frames) are read from the decoded message's class
PX4_ODOMETRY_MSG = """
uint64 timestamp
uint64 timestamp_sample
uint8 POSE_FRAME_UNKNOWN = 0
uint8 POSE_FRAME_NED = 1
uint8 POSE_FRAME_FRD = 2
uint8 pose_frame
float32[3] position
float32[4] q
uint8 VELOCITY_FRAME_UNKNOWN = 0
uint8 VELOCITY_FRAME_NED = 1
uint8 VELOCITY_FRAME_FRD = 2
uint8 VELOCITY_FRAME_BODY_FRD = 3
uint8 velocity_frame
float32[3] velocity
float32[3] angular_velocity
float32[3] position_variance
float32[3] orientation_variance
float32[3] velocity_variance
uint8 reset_counter
int8 quality
"""


@cache
def typestore(distro: str) -> Any:
    """rosbags' type store of ``distro`` (jazzy, humble), with PX4's VehicleOdometry."""
    store = get_typestore(STORES[distro])
    store.register(get_types_from_msg(PX4_ODOMETRY_MSG, PX4_ODOMETRY))
    return store


def type_hash(distro: str, typename: str) -> str:
    """The RIHS01 hash of ``typename`` (``pkg/msg/Name``) as ``distro`` defines it."""
    return str(typestore(distro).hash_rihs01(typename))


class Messages:
    """Builds and encodes the robot's messages for one configuration."""

    def __init__(self, settings: Settings) -> None:
        self.settings, self.ros = settings, settings.ros2
        self.store = typestore(self.ros.distro)
        self.types = self.store.types
        self.wrist = settings.wrist.enabled
        self.tool_offset = np.asarray(settings.tool.offset_m, dtype=float)
        world = settings.world
        self.mount = Pose.from_arrays(world.mount_position_m, world.mount_quaternion)

    def cdr(self, message: Any, typename: str) -> bytes:
        """``message`` as CDR, little-endian, with its encapsulation header."""
        return bytes(self.store.serialize_cdr(message, typename))

    def _header(self, stamp_s: float, frame: str) -> Any:
        t = self.types
        sec = math.floor(stamp_s)
        time = t["builtin_interfaces/msg/Time"](
            sec=sec, nanosec=round((stamp_s - sec) * 1e9) % 10**9
        )
        return t["std_msgs/msg/Header"](stamp=time, frame_id=frame)

    def joint_state(self, snap: Snapshot, stamp_s: float) -> Any:
        """The joints as read [rad, rad/s] (the wrist as a fourth when fitted); unknown
        values (no read yet) are NaN, as ROS's convention for a missing value."""
        ros = self.ros
        names = list(ros.joint_names)
        position = list(np.asarray(snap.joints_measured_rad, dtype=float))
        velocity = list(np.asarray(snap.velocity_rad_s, dtype=float))
        if self.wrist:
            names.append(ros.wrist_joint_name)
            position.append(float(snap.phi_measured_rad))
            velocity.append(math.nan)
        return self.types[JOINT_STATE](
            header=self._header(stamp_s, ""),
            name=names,
            position=np.asarray(position, dtype=np.float64),
            velocity=np.asarray(velocity, dtype=np.float64),
            effort=np.zeros(0, dtype=np.float64),
        )

    def _transform(self, stamp_s: float, parent: str, child: str, xyz, wxyz) -> Any:
        t = self.types
        translation = t["geometry_msgs/msg/Vector3"](
            x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])
        )
        w, x, y, z = (float(v) for v in wxyz)
        rotation = t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)
        transform = t["geometry_msgs/msg/Transform"](translation=translation, rotation=rotation)
        return t["geometry_msgs/msg/TransformStamped"](
            header=self._header(stamp_s, parent), child_frame_id=child, transform=transform
        )

    def tf(self, snap: Snapshot, stamp_s: float) -> Any | None:
        """base -> platform (the measured platform centre) -> tip (the tool offset turned
        by the wrist angle about z: kinematics/tool.py's tip); None before the first read
        (FK unknown)."""
        platform = np.asarray(snap.platform_measured_m, dtype=float)
        if not np.isfinite(platform).all():
            return None
        ros = self.ros
        phi = float(snap.tool_phi_rad) if math.isfinite(snap.tool_phi_rad) else 0.0
        turn = (math.cos(phi / 2), 0.0, 0.0, math.sin(phi / 2))
        c, s = math.cos(phi), math.sin(phi)
        x, y, z = self.tool_offset
        offset = (c * x - s * y, s * x + c * y, z)  # the wrist turns the tool about z
        return self.types[TF](
            transforms=[
                self._transform(
                    stamp_s, ros.base_frame, ros.platform_frame, platform, (1, 0, 0, 0)
                ),
                self._transform(stamp_s, ros.platform_frame, ros.tip_frame, offset, turn),
            ]
        )

    def tf_static(self, stamp_s: float) -> Any:
        """The drone's body -> the Delta's base, from the mount in the config."""
        world = self.settings.world
        return self.types[TF](
            transforms=[
                self._transform(
                    stamp_s,
                    self.ros.drone_frame,
                    self.ros.base_frame,
                    world.mount_position_m,
                    world.mount_quaternion,
                )
            ]
        )

    def _pose(self, stamp_s: float, frame: str, xyz, wxyz=(1.0, 0.0, 0.0, 0.0)) -> Any:
        t = self.types
        point = t["geometry_msgs/msg/Point"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
        w, x, y, z = (float(v) for v in wxyz)
        orientation = t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)
        pose = t["geometry_msgs/msg/Pose"](position=point, orientation=orientation)
        return t[POSE](header=self._header(stamp_s, frame), pose=pose)

    def tip_pose(self, snap: Snapshot, stamp_s: float) -> Any | None:
        """The measured tool tip in the base frame (its heading: the wrist angle about z);
        None before the first read."""
        tip = np.asarray(snap.point_measured_m, dtype=float)
        if not np.isfinite(tip).all():
            return None
        phi = float(snap.tool_phi_rad) if math.isfinite(snap.tool_phi_rad) else 0.0
        return self._pose(
            stamp_s, self.ros.base_frame, tip, (math.cos(phi / 2), 0, 0, math.sin(phi / 2))
        )

    def tip_wrench(self, snap: Snapshot, stamp_s: float) -> Any | None:
        """The tip's contact force as estimated this tick (docs/contact.md): the force the
        tip applies on what it touches, base frame [N], no torque; None while the estimate
        is not valid."""
        reading = snap.contact
        force = np.asarray(reading.force_n, dtype=float)
        if not reading.valid or not np.isfinite(force).all():
            return None
        t = self.types
        vector = t["geometry_msgs/msg/Vector3"]
        wrench = t["geometry_msgs/msg/Wrench"](
            force=vector(x=float(force[0]), y=float(force[1]), z=float(force[2])),
            torque=vector(x=0.0, y=0.0, z=0.0),
        )
        return t[WRENCH](header=self._header(stamp_s, self.ros.base_frame), wrench=wrench)

    def tip_world(self, snap: Snapshot, stamp_s: float, frame: str | None = None) -> Any | None:
        """The measured tip in the world while holding in it, in ``frame`` (None: ``[ros2]
        world_frame``): hold-in-world's own figure where it has one (the simulated drone's
        true pose), else the measured tip carried by the latest pose sample of the drone
        and the mount; None when not holding or nothing is known yet."""
        extra = snap.extra or {}
        measured = extra.get("measured_world_m")
        heading = extra.get("measured_heading_world_rad")
        drone = extra.get("drone_pose")
        tip = np.asarray(snap.point_measured_m, dtype=float)
        if measured is None and drone is not None and np.isfinite(tip).all():
            base = Pose.from_arrays(drone[:3], drone[3:]) @ self.mount
            measured = base.apply(tip)
            w, x, y, z = base.quaternion
            yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
            heading = yaw + (snap.tool_phi_rad if math.isfinite(snap.tool_phi_rad) else 0.0)
        if measured is None or not np.isfinite(np.asarray(measured, dtype=float)).all():
            return None
        turn = (1.0, 0.0, 0.0, 0.0)
        if heading is not None and math.isfinite(heading):
            turn = (math.cos(heading / 2), 0.0, 0.0, math.sin(heading / 2))
        return self._pose(stamp_s, frame or self.ros.world_frame, measured, turn)

    def diagnostics(
        self, snap: Snapshot, stamp_s: float, extra: dict[str, str] | None = None
    ) -> Any:
        """One status of the robot: OK, WARN (a warning, a loop that misses ticks) or ERROR
        (e-stop, a fault), with the loop's health, the mode, torque and the faults as
        key-values; ``extra``: more key-values (the ROS inputs' counters)."""
        t = self.types
        status_type = t["diagnostic_msgs/msg/DiagnosticStatus"]
        window = snap.loop_window
        level, message = diagnostic_level(snap)
        values = {
            "mode": snap.mode,
            "torque": str(snap.torque).lower(),
            "estopped": str(snap.estopped).lower(),
            "faults": "; ".join(f.reason for f in snap.faults) or "none",
            "loop_rate_hz": f"{window.measured_hz:.1f}",
            "lateness_p99_ms": f"{window.jitter_p99_ms:.3f}",
            "overruns_last_10s": str(window.overruns),
            "loop_health": classify(window).level,
            "tick": str(snap.tick),
            **(extra or {}),
        }
        key_value = t["diagnostic_msgs/msg/KeyValue"]
        status = status_type(
            level=level,
            name=f"{self.ros.node_name}: robot",
            message=message,
            hardware_id=snap.info.backend_description or snap.info.backend,
            values=[key_value(key=k, value=v) for k, v in values.items()],
        )
        return t[DIAGNOSTICS](header=self._header(stamp_s, ""), status=[status])


OK, WARN, ERROR = 0, 1, 2  # diagnostic_msgs/DiagnosticStatus's levels


def diagnostic_level(snap: Snapshot) -> tuple[int, str]:
    """The robot's diagnostic level and its message: ERROR (e-stop, a fault), WARN (a
    warning; the loop's health light amber or red, as the page shows it:
    app/control/loop_health.py) or OK (the mode)."""
    if snap.estopped or snap.faults:
        return ERROR, "e-stop" if snap.estopped else snap.faults[0].reason
    if snap.warning:
        return WARN, snap.warning
    health = classify(snap.loop_window)
    if health.level in ("amber", "red"):
        return WARN, f"the loop ({health.level}): {'; '.join(health.reasons)}"
    return OK, snap.mode

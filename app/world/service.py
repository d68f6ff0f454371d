"""The world side of the server: the external pose tracker, its listeners, hold sources."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from app.control.errors import GoalRejected
from app.world.drone_sim import DroneSimParams, SimulatedDrone
from app.world.hold import HoldSource, PoseProvider, SimulatedDroneProvider, TrackerProvider
from app.world.inputs import MavlinkPoseListener, PoseInput, UdpPoseListener
from app.world.poses import PoseTracker
from hardware.bus import SimulatedBus
from kinematics import Pose

if TYPE_CHECKING:
    from app.control.controller import Controller


def base_motion(
    mount: Pose,
    drone_wxyz: np.ndarray,
    drone_acceleration: np.ndarray,
    omega_body: np.ndarray,
    omega_dot_body: np.ndarray,
    drone_position: np.ndarray | None = None,
    drone_velocity: np.ndarray | None = None,
):
    """The Delta base's motion from the drone's: attitude R_d R_m, the acceleration of the
    base origin (the drone's plus the lever arm's: R_d (w' x p_m + w x (w x p_m))), and the
    turning rates in the base frame (R_m^T w, R_m^T w'), as hardware.sim.BaseMotion. With
    the drone's position [m] (world) also the base origin p_d + R_d p_m and its velocity
    v_d + R_d (w x p_m) [m/s] (``drone_velocity`` world, None: still): the base pose
    drone @ mount, which moves a twin's plates fixed in the world."""
    from hardware.sim import BaseMotion

    drone = Pose(np.zeros(3), np.asarray(drone_wxyz, dtype=float))
    base = drone @ mount
    w, w_dot = np.asarray(omega_body, dtype=float), np.asarray(omega_dot_body, dtype=float)
    arm = np.asarray(mount.position, dtype=float)
    lever = np.cross(w_dot, arm) + np.cross(w, np.cross(w, arm))
    to_base = mount.rotation.T
    position, velocity = None, (0.0, 0.0, 0.0)
    if drone_position is not None:
        position = tuple(np.asarray(drone_position, dtype=float) + drone.rotation @ arm)
        moving = np.zeros(3) if drone_velocity is None else np.asarray(drone_velocity, float)
        velocity = tuple(moving + drone.rotation @ np.cross(w, arm))
    return BaseMotion(
        tuple(base.quaternion),
        tuple(np.asarray(drone_acceleration, dtype=float) + drone.rotation @ lever),
        tuple(to_base @ w),
        tuple(to_base @ w_dot),
        position_m=position,
        velocity_m_s=velocity,
    )


class WorldService:
    """Owns the external pose trackers (the drone's, ``tracker``; a platform marker's,
    ``platform``) and their listeners; builds hold sources for the loop."""

    def __init__(self, controller: Controller) -> None:
        self.controller = controller
        world = controller.settings.world
        self.mount = Pose.from_arrays(world.mount_position_m, world.mount_quaternion)
        self.tracker = PoseTracker(world.stale_after_s, world.lost_after_s, world.max_jump_m)
        # a motion-capture marker on the platform (body "platform" on the pose input): a
        # calibration run's measurement (app/calibration/procedure.py pose_input)
        self.platform = PoseTracker(world.stale_after_s, world.lost_after_s, world.max_jump_m)
        self._listeners: list[PoseInput] = []
        token = controller.settings.server.token
        if world.udp_port is not None:
            listener = UdpPoseListener(
                self.tracker,
                world.udp_port,
                platform=self.platform,
                token=token,
                trusted=world.udp_trusted,
            )
            self._listeners.append(listener.start())
        if world.mavlink_url is not None:
            listener = MavlinkPoseListener(
                self.tracker,
                world.mavlink_url,
                token=token,
                trusted=world.mavlink_trusted,
                signing_key=world.mavlink_signing_key_bytes,
            )
            self._listeners.append(listener.start())

    def tracker_for(self, body: str) -> PoseTracker:
        """The tracker of ``body`` ("drone" or "platform"); ValueError for another."""
        trackers = {"drone": self.tracker, "platform": self.platform}
        if body not in trackers:
            raise ValueError(f"body: {body!r} is not 'drone' or 'platform'")
        return trackers[body]

    def udp_errors(self) -> int | None:
        """Datagrams the UDP pose input refused (None without one)."""
        udp = [x for x in self._listeners if isinstance(x, UdpPoseListener)]
        return udp[0].errors + udp[0].refused if udp else None

    def sources(self) -> list[dict[str, Any]]:
        """Every pose source and what it takes (GET /api/mav/pose ``sources``): http and
        websocket (rule "token" when a token is set, else "open"; no counters of their own),
        udp and mavlink (enabled when configured; alive, rule, counters, last_error)."""
        rule = "open" if self.controller.settings.server.token is None else "token"
        blank = {"alive": None, "accepted": None, "errors": None, "refused": None}
        blank |= {"restarts": None, "last_error": None}
        out = [
            {"name": name, "enabled": True, "rule": rule, **blank} for name in ("http", "websocket")
        ]
        running = {listener.name: listener for listener in self._listeners}
        world = self.controller.settings.world
        token = self.controller.settings.server.token
        for name, trusted in (("udp", world.udp_trusted), ("mavlink", world.mavlink_trusted)):
            if name in running:
                out.append(running[name].status())
                continue
            off = "open" if token is None else ("trusted" if trusted else "refused")
            out.append({"name": name, "enabled": False, "rule": off, **blank})
        return out

    def restart_inputs(self) -> None:
        """Restart every listener thread that has died (POST /api/reset); one that cannot
        be reopened says why in its ``last_error`` and stays down."""
        for listener in self._listeners:
            try:
                listener.restart()
            except OSError as exc:
                listener.last_error = f"restart failed: {exc}"

    def close(self) -> None:
        for listener in self._listeners:
            listener.stop()
        self.level_base()

    def provider(self, simulated: DroneSimParams | None) -> PoseProvider:
        self.level_base()
        if simulated is not None:
            hook = self._feel_hook()
            drone = SimulatedDrone(simulated)
            return SimulatedDroneProvider(drone, hook, pose=hook is not None)
        return TrackerProvider(self.tracker)

    def _feel_hook(self):
        """On the simulated robot, the drone's motion moves the twin's base (else None):
        its attitude, acceleration and turning, and its pose (the twin's plates fixed in
        the world stay put)."""
        bus = self.controller.bus
        if not isinstance(bus, SimulatedBus):
            return None
        mount = self.mount

        def feel(quaternion, acceleration, omega, omega_dot, position, velocity) -> None:
            motion = base_motion(
                mount, quaternion, acceleration, omega, omega_dot, position, velocity
            )
            bus.set_base_motion(motion)

        return feel

    def level_base(self) -> None:
        """Back to a level, still base (after a simulated-drone hold)."""
        bus = self.controller.bus
        if isinstance(bus, SimulatedBus):
            from hardware.sim import BaseMotion

            bus.set_base_motion(BaseMotion())

    def hold_source(
        self,
        goal_world: np.ndarray | None,
        provider: PoseProvider,
        compensate: bool,
        heading_rad: float | None = None,
    ) -> HoldSource:
        """A hold source; ``goal_world`` None holds the tool where it is now. With a wrist it
        also keeps the tool's world heading ``heading_rad`` [rad] (None: the heading now);
        without one a heading is refused (GoalRejected naming the field)."""
        controller = self.controller
        if goal_world is None:
            seen = provider.observe(0.0)
            if seen.pose is None:
                reason = f"no drone pose yet (source {seen.state}): cannot hold 'current'"
                raise GoalRejected(reason)
            here = controller.snapshot().point_measured_m
            goal_world = (seen.pose @ self.mount).apply(here)
        lead = controller.settings.world.servo_lag_s if compensate else None
        gate = controller.gate
        wrist = None
        if gate.wrist_min_rad is not None and gate.wrist_max_rad is not None:
            wrist = (gate.wrist_min_rad, gate.wrist_max_rad)
        elif heading_rad is not None:
            raise GoalRejected("heading_rad: no wrist axis is configured ([wrist] enabled = false)")
        if heading_rad is not None and not math.isfinite(heading_rad):
            raise GoalRejected(f"heading_rad: must be finite, got {heading_rad}")
        return HoldSource(
            goal_world,
            provider,
            self.mount,
            gate,
            lambda: controller.measured_point,
            lead,
            wrist=wrist,
            measured_phi=lambda: controller.measured_phi,
            heading_rad=heading_rad,
        )

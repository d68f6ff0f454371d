"""Hold-in-world mode: keep the tool at a fixed world point while the drone drifts.

Each tick (thesis eq. 5.1-5.2): take the latest drone pose, move the world goal into the
base frame through the drone pose and the mount, clamp it onto the workspace (the time
outside is counted), and command it. With latency compensation the pose is first
predicted forward by its age plus the servos' lag, from its linear and angular velocity
(supplied by the source or estimated from the last two samples).

Goals and measurements are the tool tip (with a ``[tool]`` offset, the tip is held, not the
platform). With a wrist (beyond the thesis) the tool's heading in the world is held too:
each tick the wrist angle is the one that keeps the world heading under the (predicted)
base attitude, ``phi = heading - yaw`` wrapped for a level base (app/world/heading.py),
moved into the wrist's limits (held at the limit, and said so, when it cannot be), and the
setpoint carries it; the tip goal is converted to the base frame as without a wrist.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from app.control.gate import Gate
from app.control.sources import Progress, Setpoint
from app.world.drone_sim import SimulatedDrone
from app.world.heading import fit_to_limits, tool_heading, wrist_angle
from app.world.poses import PoseTracker
from kinematics import Pose
from kinematics.pose import quaternion_multiply


@dataclass(frozen=True)
class Observation:
    """A pose as the loop sees it: health, age [s], pose, velocity and angular velocity."""

    state: str  # ok | stale | lost | none
    age_s: float
    pose: Pose | None = None
    velocity_m_s: np.ndarray | None = None
    angular_velocity_rad_s: np.ndarray | None = None  # body frame


class PoseProvider(Protocol):
    def observe(self, t_s: float) -> Observation: ...

    def true_pose(self, t_s: float) -> Pose | None:
        """The true pose when known (simulation), for measuring the world error."""


def angular_velocity(q_old: np.ndarray, q_new: np.ndarray, dt_s: float) -> np.ndarray:
    """Body-frame angular velocity [rad/s] turning q_old into q_new in dt_s."""
    delta = quaternion_multiply(q_old * np.array([1, -1, -1, -1]), q_new)
    delta = delta if delta[0] >= 0 else -delta
    angle = 2.0 * math.atan2(float(np.linalg.norm(delta[1:])), float(delta[0]))
    axis = delta[1:] / max(float(np.linalg.norm(delta[1:])), 1e-15)
    return axis * angle / dt_s


def predict(pose: Pose, velocity: np.ndarray, omega_body: np.ndarray, ahead_s: float) -> Pose:
    """The pose ``ahead_s`` later at constant linear and angular velocity."""
    angle = float(np.linalg.norm(omega_body)) * ahead_s
    if angle > 0:
        axis = omega_body / np.linalg.norm(omega_body)
        turn = np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])
        quaternion = quaternion_multiply(pose.quaternion, turn)
    else:
        quaternion = pose.quaternion
    return Pose(pose.position + velocity * ahead_s, quaternion)


class SimulatedDroneProvider:
    """Observations of a SimulatedDrone: its measurement stream, latency and rate included.

    ``feel`` (optional) receives the drone's true attitude, acceleration [m/s^2, world],
    body rate [rad/s] and its rate of change [rad/s^2, body frame] each tick, so a simulated
    arm's base moves with the drone (gravity and base motion act on it); with ``pose``
    also its true position [m] and velocity [m/s] (world), two more arguments (a twin's
    plates fixed in the world follow them).
    """

    def __init__(
        self,
        drone: SimulatedDrone,
        feel: Callable[..., None] | None = None,
        *,
        pose: bool = False,
    ) -> None:
        self.drone = drone
        self.feel = feel
        self.pose = pose

    def observe(self, t_s: float) -> Observation:
        if self.feel is not None:
            self._feel(t_s)
        stamp, pose, velocity = self.drone.measured(t_s)
        period = 1.0 / self.drone.params.rate_hz
        _, previous, _ = self.drone.measured(t_s - period)
        omega = angular_velocity(previous.quaternion, pose.quaternion, period)
        return Observation("ok", t_s - stamp, pose, velocity, omega)

    def true_pose(self, t_s: float) -> Pose:
        return self.drone.true_state(t_s)[0]

    def _feel(self, t_s: float) -> None:
        h = 1e-3  # the drone's true motion is smooth: central differences suffice
        before, now, after = (self.drone.true_state(t_s + k * h)[0] for k in (-1, 0, 1))
        rate_before = angular_velocity(before.quaternion, now.quaternion, h)
        rate_after = angular_velocity(now.quaternion, after.quaternion, h)
        omega = 0.5 * (rate_before + rate_after)
        omega_dot = (rate_after - rate_before) / h
        felt = (now.quaternion, self.drone.acceleration(t_s), omega, omega_dot)
        if self.pose:
            felt += (now.position, self.drone.true_state(t_s)[1])
        self.feel(*felt)


class TrackerProvider:
    """Observations of an external source (motion capture, MAVLink) through its tracker."""

    def __init__(self, tracker: PoseTracker) -> None:
        self.tracker = tracker
        self._last: tuple[float, np.ndarray] | None = None
        self._omega = np.zeros(3)

    def observe(self, t_s: float) -> Observation:
        state, age = self.tracker.health()
        sample, velocity = self.tracker.latest()
        if sample is None:
            return Observation(state, age)
        omega = sample.angular_velocity_rad_s
        if omega is None:
            if self._last is not None and sample.t_s > self._last[0]:
                dt = sample.t_s - self._last[0]
                self._omega = angular_velocity(self._last[1], sample.quaternion, dt)
            omega = self._omega
        self._last = (sample.t_s, sample.quaternion)
        return Observation(state, age, sample.pose, velocity, omega)

    def true_pose(self, t_s: float) -> Pose | None:
        return None


class HoldSource:
    """Goal source of mode ``hold-world`` (see module docstring).

    goal_world_m: the tip's world goal (3,) [m]; lead_s: None for the plain method, else
    the servo lag [s] predicted over beside the pose's age. With a wrist, ``wrist`` holds
    its limits (low, high) [rad], ``measured_phi`` reads its angle [rad] and
    ``heading_rad`` is the world heading to keep [rad] (None: the tool's heading at the
    first pose seen).
    """

    name = "hold-world"

    def __init__(
        self,
        goal_world_m: np.ndarray,
        provider: PoseProvider,
        mount: Pose,
        gate: Gate,
        measured: Callable[[], np.ndarray],
        lead_s: float | None,
        wrist: tuple[float, float] | None = None,
        measured_phi: Callable[[], float] | None = None,
        heading_rad: float | None = None,
    ) -> None:
        self.goal_world = np.asarray(goal_world_m, dtype=np.float64)
        self.provider, self.mount, self.gate, self.measured = provider, mount, gate, measured
        self.lead_s = lead_s  # None: plain method (thesis); else compensate age + lead_s
        self.t_s = 0.0
        self.outside_s = 0.0
        self.finished = False
        self.duration_s: float | None = None
        self.approach_s = 1.0
        self._start: np.ndarray | None = None
        self.wrist, self.heading = wrist, heading_rad
        self.measured_phi = measured_phi if measured_phi is not None else lambda: 0.0
        self._start_phi: float | None = None
        self._phi: float | None = None  # the last wrist angle commanded
        self.base_pose: Pose | None = None

    def progress(self) -> Progress:
        """How far a timed hold (a run) is (app/control/sources.py's ``Progressing``)."""
        t, total = self.t_s, self.duration_s if self.duration_s is not None else math.inf
        phase = "approach" if t < self.approach_s else "hold"
        return Progress.at(phase, t, self.approach_s, total - self.approach_s)

    def next(self, dt_s: float) -> Setpoint:
        self.t_s += dt_s
        self.finished = self.duration_s is not None and self.t_s >= self.duration_s
        seen = self.provider.observe(self.t_s)
        if seen.state in ("lost", "none") or seen.pose is None:
            return Setpoint(
                fault=f"drone pose {seen.state} (age {seen.age_s:.3f} s)",
                phase="hold",
                finished=True,
            )
        if seen.state == "stale":
            return Setpoint(
                warning=f"drone pose stale ({seen.age_s * 1e3:.0f} ms): holding",
                phase="hold",
                finished=self.finished,
            )
        pose = seen.pose
        if self.lead_s is not None:
            ahead = seen.age_s + self.lead_s
            pose = predict(pose, seen.velocity_m_s, seen.angular_velocity_rad_s, ahead)
        base = pose @ self.mount
        self.base_pose = base  # the base's pose this tick (a world press turns with it)
        goal_base = base.apply_inverse(self.goal_world)
        phi, limited = self._wrist_angle(seen.pose @ self.mount, base)
        at = 0.0 if phi is None else phi
        commanded = self.gate.clamp_point(self._blend_in(goal_base), at)
        outside = not self.gate.inside(goal_base, at)
        self.outside_s += dt_s if outside and self.t_s >= self.approach_s else 0.0
        return Setpoint(
            point_m=commanded,
            goal_m=goal_base,
            phi_rad=phi,
            phase="approach" if self.t_s < self.approach_s else "hold",
            finished=self.finished,
            extra=self._world(outside, seen.age_s, limited, self._now(seen)),
        )

    def _wrist_angle(self, seen_base: Pose, base: Pose) -> tuple[float | None, bool]:
        """The wrist angle [rad] keeping the world heading under the (predicted) base
        ``base``, blended in from the wrist's angle over the approach, and whether the
        limits cut it; (None, False) without a wrist."""
        if self.wrist is None:
            return None, False
        if self.heading is None:  # keep the heading the tool has now
            self.heading = tool_heading(seen_base.rotation, self.measured_phi())
        if self._start_phi is None:
            self._start_phi = self.measured_phi()
        near = self._start_phi if self._phi is None else self._phi
        wanted = wrist_angle(base.rotation, self.heading)
        phi, limited = fit_to_limits(wanted, *self.wrist, near)
        if self.t_s < self.approach_s:  # both ends inside the limits: so is the blend
            s = self.t_s / self.approach_s
            phi = self._start_phi + (10 * s**3 - 15 * s**4 + 6 * s**5) * (phi - self._start_phi)
        self._phi = phi
        return phi, limited

    def _blend_in(self, goal_base: np.ndarray) -> np.ndarray:
        """Over the first approach_s, slide from where the robot was onto the moving goal
        (minimum-jerk weight), so starting the mode never steps the servos."""
        if self._start is None:
            self._start = self.measured().copy()
        if self.t_s >= self.approach_s:
            return goal_base
        s = self.t_s / self.approach_s
        weight = 10 * s**3 - 15 * s**4 + 6 * s**5
        return self._start + weight * (goal_base - self._start)

    def drone_pose(self, truth: Pose | None = None) -> list[float] | None:
        """The drone's body-to-world pose this source works from, as position [m] and
        quaternion (w, x, y, z): the simulated drone's truth, else the external tracker's
        latest sample (never ``provider.observe``, which updates state); None: none yet."""
        pose = truth
        tracker = getattr(self.provider, "tracker", None)
        if pose is None and tracker is not None:
            sample, _ = tracker.latest()
            pose = sample.pose if sample is not None else None
        if pose is None:
            return None
        return [*np.asarray(pose.position).tolist(), *np.asarray(pose.quaternion).tolist()]

    @staticmethod
    def _now(seen: Observation) -> Pose:
        """The drone's pose now: the observed one carried forward by its age at its
        velocity (the tool is measured now; the pose is ``age_s`` old)."""
        if seen.velocity_m_s is None or seen.angular_velocity_rad_s is None:
            return seen.pose
        return predict(seen.pose, seen.velocity_m_s, seen.angular_velocity_rad_s, seen.age_s)

    def _world(
        self, outside: bool, age_s: float, limited: bool = False, seen: Pose | None = None
    ) -> dict:
        """The hold's world-frame figures: the tip's world goal, the tip measured in the
        world [m] (through the true drone pose in simulation, else through ``seen``, the pose
        input's latest sample carried forward by its age: what the pose input says,
        ``measured_world_from`` "pose input"), the goal outside, the pose's age [s] and
        the drone's pose."""
        truth = self.provider.true_pose(self.t_s)
        measured_world = None
        through = truth if truth is not None else seen
        if through is not None:
            measured_world = (through @ self.mount).apply(self.measured()).tolist()
        world = {
            "goal_world_m": self.goal_world.tolist(),
            "measured_world_m": measured_world,
            "outside": outside,
            "pose_age_s": age_s,
            "drone_pose": self.drone_pose(truth),
            "measured_world_from": "truth" if truth is not None else "pose input",
        }
        if self.wrist is not None:  # the heading: goal, measured (true pose, wrist read)
            measured_heading = None
            if truth is not None:
                turned = (truth @ self.mount).rotation
                measured_heading = tool_heading(turned, self.measured_phi())
            world["heading_world_rad"] = self.heading
            world["measured_heading_world_rad"] = measured_heading
            world["heading_limited"] = limited
        return world

"""Motor sizing over a workspace region (thesis ch. 4.2, "Motor Selection and Sizing").

Three requirements, each a worst case over a grid of platform positions:

- static torque: holding the platform against gravity when the drone tilts up to a
  limit (90 deg: its plane vertical, the thesis's worst case);
- peak torque: the same gravity, plus an acceleration of given size in any direction
  and the velocity terms at the given speed;
- joint speed: the platform moving at the given speed in any direction.

At rest the torques are linear in gravity, tau = A(P) g, and the acceleration part is
linear too, B(P) a; so the worst gravity in a cone and the worst acceleration direction
have closed forms (no sampling). Only the velocity terms (quadratic in v) are sampled
over directions. Joint speed is qd_i = (w_i . v) / (w_i . C_i') (differential.py), whose
largest value over |v| = s is s |w_i| / |w_i . C_i'|, exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ._arrays import triple_floats
from .dynamics import MassModel, inverse_dynamics
from .rotary import RotaryDelta

RPM_PER_RAD_S = 60.0 / (2.0 * np.pi)


@dataclass(frozen=True)
class Servo:
    """A servo's straight torque-speed line: tau_max(w) = stall (1 - w / no_load).

    Attributes:
        name: for reports.
        stall_nm: stall torque [N m]; no_load_rpm: speed without load [rpm].
    """

    name: str
    stall_nm: float
    no_load_rpm: float

    def torque_at(self, rpm: Any) -> np.ndarray:
        """Largest torque [N m] at speed ``rpm`` (0 beyond the no-load speed)."""
        return self.stall_nm * np.clip(1.0 - np.asarray(rpm) / self.no_load_rpm, 0.0, 1.0)


XM430_W210_12V = Servo("XM430-W210 @ 12.0 V", stall_nm=3.0, no_load_rpm=77.0)
"""Robotis e-Manual: stall 3.0 N m at 2.3 A, no load 77 rpm (12.0 V)."""
XM430_W210_11V1 = Servo("XM430-W210 @ 11.1 V", stall_nm=2.7, no_load_rpm=70.0)
"""Robotis e-Manual: stall 2.7 N m at 2.1 A, no load 70 rpm (11.1 V)."""
XM430_W210_THESIS = Servo("XM430-W210 (thesis: 2 N m, 72 rpm)", stall_nm=2.0, no_load_rpm=72.0)


class Worst(NamedTuple):
    """A worst case: the value, where it happens [m], and which joint (0-2)."""

    value: float
    point: tuple[float, float, float]
    joint: int


class Sizing(NamedTuple):
    """Requirements and the servo check (see :func:`size_motors`).

    static_nm, peak_nm: largest |torque| [N m]; speed_rpm: largest joint speed [rpm].
    available_nm: the servo's torque at ``speed_rpm``; torque_margin: available / peak;
    speed_margin: no-load speed / speed_rpm; passes: both margins >= 1.
    points: grid points used (reachable, not singular); skipped: the others.
    """

    static_nm: Worst
    peak_nm: Worst
    speed_rpm: Worst
    servo: Servo
    available_nm: float
    torque_margin: float
    speed_margin: float
    passes: bool
    points: int
    skipped: int


def region_grid(lower: Any, upper: Any, per_axis: int = 9) -> np.ndarray:
    """Grid over the box [lower, upper] [m], shape (per_axis^3, 3)."""
    axes = [np.linspace(a, b, per_axis) for a, b in zip(lower, upper, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def cone_extremes(a: np.ndarray, axis: np.ndarray, half_angle: float) -> tuple:
    """Largest and smallest a . u over unit u within ``half_angle`` [rad] of unit ``axis``.

    a: shape (*, 3). Returns two arrays shaped (*): the maximum is |a| cos(max(0, phi -
    half_angle)), phi the angle between a and the axis; the minimum is the same for -a.
    """
    norm = np.linalg.norm(a, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        phi = np.arccos(np.clip(a @ axis / norm, -1.0, 1.0))
    phi = np.nan_to_num(phi)
    largest = norm * np.cos(np.maximum(0.0, phi - half_angle))
    smallest = -norm * np.cos(np.maximum(0.0, np.pi - phi - half_angle))
    return largest, smallest


def _fibonacci_sphere(n: int) -> np.ndarray:
    """n nearly uniform unit vectors, shape (n, 3)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    angle = np.pi * (1.0 + 5.0**0.5) * k
    rho = np.sqrt(1.0 - z * z)
    return np.stack([rho * np.cos(angle), rho * np.sin(angle), z], -1)


def _worst(values: np.ndarray, points: np.ndarray) -> Worst:
    """The largest entry of values (N, 3) and where it is."""
    index = np.unravel_index(int(np.nanargmax(values)), values.shape)
    return Worst(float(values[index]), triple_floats(points[index[0]], "point"), int(index[1]))


def size_motors(
    robot: RotaryDelta,
    mass: MassModel,
    points: Any,
    *,
    payload_kg: float = 0.2,
    acceleration_m_s2: float = 4.0,
    speed_m_s: float = 0.5,
    tilt_deg: float = 90.0,
    gravity_m_s2: float = 9.81,
    servo: Servo = XM430_W210_12V,
    velocity_directions: int = 64,
    min_dexterity: float = 0.02,
    margin_m: float = 0.0,
) -> Sizing:
    """Worst static torque, peak torque and joint speed over ``points``; the servo check.

    Args:
        robot, mass: the Delta and its mass model (without payload).
        points: platform positions of the region [m], shape (N, 3); unreachable or
            near-singular ones (dexterity below ``min_dexterity``) are skipped.
        payload_kg: added to the platform [kg] (thesis: 0.2).
        acceleration_m_s2: platform acceleration in any direction (thesis: 4).
        speed_m_s: platform speed in any direction (thesis: 0.5).
        tilt_deg: gravity within this angle of -z (90: drone plane vertical).
        servo: its torque-speed line; velocity_directions: samples of the speed's
            direction for the velocity terms of the peak.
        margin_m: skip points nearer than this to the workspace boundary [m], where
            joint speeds grow without bound.
    """
    loaded = mass.with_payload(payload_kg)
    pts = np.asarray(points, float).reshape(-1, 3)
    q = robot.ik(pts).joints
    usable = robot.fk(q).ok & (np.nan_to_num(robot.dexterity(q)) > min_dexterity)
    usable &= robot.signed_distance(pts) <= -margin_m
    pts, q = pts[usable], q[usable]
    static, peak = _torques(
        robot,
        loaded,
        pts,
        gravity_m_s2 * np.array([0.0, 0.0, -1.0]),
        np.radians(tilt_deg),
        acceleration_m_s2,
        speed_m_s * _fibonacci_sphere(velocity_directions),
    )
    eye = np.eye(3)
    inverse_jacobian = np.stack([robot.joint_velocity(q, e) for e in eye], -1)
    speed = speed_m_s * np.linalg.norm(inverse_jacobian, axis=-1) * RPM_PER_RAD_S
    worst_static, worst_peak = _worst(static, pts), _worst(peak, pts)
    worst_speed = _worst(speed, pts)
    available = float(servo.torque_at(worst_speed.value))
    torque_margin = available / worst_peak.value
    speed_margin = servo.no_load_rpm / worst_speed.value
    return Sizing(
        worst_static,
        worst_peak,
        worst_speed,
        servo,
        available,
        torque_margin,
        speed_margin,
        bool(torque_margin >= 1.0 and speed_margin >= 1.0),
        int(usable.sum()),
        int((~usable).sum()),
    )


def _torques(
    robot: RotaryDelta,
    loaded: MassModel,
    pts: np.ndarray,
    gravity: np.ndarray,
    tilt_rad: float,
    acceleration: float,
    velocities: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Worst static and peak |torque| per point and joint [N m], each (N, 3).

    Gravity anywhere within tilt_rad of ``gravity``'s direction (same magnitude),
    acceleration of the given size in any direction, velocities as sampled (M, 3).
    """
    zero, eye = np.zeros_like(pts), np.eye(3)
    per_gravity = np.stack(
        [inverse_dynamics(robot, loaded, pts, zero, zero, gravity=e) for e in eye], -1
    )  # (N, joint, gravity axis) [N m per m/s^2]
    per_accel = np.stack(
        [inverse_dynamics(robot, loaded, pts, zero, e, gravity=(0, 0, 0)) for e in eye], -1
    )
    g = float(np.linalg.norm(gravity))
    most, least = cone_extremes(per_gravity, gravity / max(g, 1e-300), tilt_rad)
    most, least = g * most, g * least
    moving = inverse_dynamics(
        robot, loaded, pts[:, None, :], velocities[None], zero[:, None, :], gravity=(0, 0, 0)
    )  # (N, directions, joint): velocity terms only
    worst_sum = np.maximum((moving + most[:, None]).max(1), -(moving + least[:, None]).min(1))
    peak = worst_sum + acceleration * np.linalg.norm(per_accel, axis=-1)
    return np.maximum(most, -least), peak

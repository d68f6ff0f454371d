"""Every sample of a planned program through what the live loop checks, all violations.

The same limits as the gate (app/control/gate.py) and the run check
(app/runs/feasibility.py), on the samples the loop would command at its period, but
collected rather than raised at the first: per program line and kind of check, the first
offending sample (its time and point) and the worst value on that line. Checks:

- ``workspace``: inside the reachable workspace with the gate's margin;
- ``ceiling``: the platform no higher than ``limits.z_max_m``;
- ``ik``: a joint solution on the branch the loop follows (app/control/branch.py);
- ``joint_limit``: each joint within its calibrated limits;
- ``joint_speed``: the joint step from one sample to the next within the gate's per-tick
  step (``limits.joint_speed_rad_s`` times the period), what the loop would clip;
- ``joint_acceleration``: qdd from the acceleration kinematics (thesis eq. 3.70 ff.,
  kinematics/differential.py) within ``programs.joint_acceleration_rad_s2``;
- ``singularity``: 1/cond(J) >= the gate's ``min_dexterity``;
- ``torque``: the rotary Delta's inverse dynamics (thesis ch. 3.2, kinematics/dynamics.py)
  against the servo's torque-speed line tau_max(w) = stall (1 - w / no_load)
  (kinematics/sizing.py; the XM430-W210 at 12 V, the same 3.0 N m and 77 rpm as the
  twin's servo model, hardware/sim/xm430.py), |tau| / tau_max <= ``max_torque_ratio``;
- with a wrist (A words): ``wrist_limit``, phi within the wrist's limits, and
  ``wrist_speed``, its step from one sample to the next within the gate's per-tick step
  (``wrist.max_speed_rad_s`` times the period). The platform centre the checks see is
  then tip - Rz(phi) d (d the tool offset), its velocity and acceleration with the
  turning offset's terms: - phi' Rz'(phi) d and - phi'' Rz'(phi) d + phi'^2 (Rz(phi) d)_xy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.control.branch import follow_branch
from app.control.gate import Gate
from app.control.model import dynamics_robot
from kinematics import RotaryDelta
from kinematics.dynamics import MassModel, inverse_dynamics_joints
from kinematics.sizing import RPM_PER_RAD_S, Servo

KINDS = (
    "workspace",
    "ceiling",
    "ik",
    "joint_limit",
    "joint_speed",
    "joint_acceleration",
    "singularity",
    "torque",
    "wrist_limit",
    "wrist_speed",
)


@dataclass(frozen=True)
class Violation:
    """One check failed on one program line: its first offending sample's time t_s [s]
    from the program's start and point_m (3,) [m, base frame]; message: what, in words."""

    line: int
    kind: str
    message: str
    t_s: float
    point_m: tuple[float, float, float]


@dataclass(frozen=True)
class VerifyLimits:
    """What a sample must satisfy beyond the gate: joint acceleration [rad/s^2]; the
    servo, the mass model and the largest torque ratio (None: no torque check)."""

    joint_acceleration_rad_s2: float
    servo: Servo | None
    mass: MassModel | None
    max_torque_ratio: float


@dataclass(frozen=True)
class Verification:
    """All violations (by time) and the worst values over the samples that had joints:
    peak joint speed [rad/s] and acceleration [rad/s^2], lowest 1/cond(J), highest torque
    ratio (None without a torque check). NaN when no sample had joints."""

    violations: list[Violation]
    peak_joint_speed_rad_s: float
    peak_joint_acceleration_rad_s2: float
    worst_dexterity: float
    worst_torque_ratio: float | None


def _collect(
    kind: str,
    bad: np.ndarray,
    value: np.ndarray,
    lines: np.ndarray,
    times: np.ndarray,
    points: np.ndarray,
    message,
) -> list[Violation]:
    """One Violation per line with a bad sample: its first one, the line's worst value.

    Lines do not decrease with time (a program runs forward), so each line's bad samples
    are one run of ``flatnonzero(bad)``.
    """
    index = np.flatnonzero(bad)
    if not index.size:
        return []
    bad_lines = lines[index]
    starts = np.flatnonzero(np.concatenate([[True], bad_lines[1:] != bad_lines[:-1]]))
    worst = np.maximum.reduceat(value[index], starts)
    out = []
    for start, worst_value in zip(starts, worst, strict=True):
        i = int(index[start])
        point = points[i]
        out.append(
            Violation(
                int(lines[i]),
                kind,
                message(float(worst_value), i),
                float(times[i]),
                (float(point[0]), float(point[1]), float(point[2])),
            )
        )
    return out


def _platform(gate: Gate, points, velocity, acceleration, wrist):
    """The platform centre's points, velocities, accelerations (N, 3) (see module)."""
    if wrist is None:  # phi = 0: a constant shift, the same velocity and acceleration
        return gate.platform(points), velocity, acceleration
    phi, phid, phidd = (np.asarray(w, dtype=np.float64) for w in wrist)
    origin = np.zeros_like(points)
    turned = gate.tip(origin, phi)  # Rz(phi) d
    ahead = gate.tip(origin, phi + math.pi / 2)  # Rz(phi + pi/2) d: its xy is Rz'(phi) d
    ahead[:, 2] = 0.0
    flat = turned.copy()
    flat[:, 2] = 0.0
    p = points - turned
    pd = velocity - phid[:, None] * ahead
    pdd = acceleration - phidd[:, None] * ahead + (phid**2)[:, None] * flat
    return p, pd, pdd


def _check_wrist(gate: Gate, phi: np.ndarray, period_s: float, add) -> None:
    """The wrist's limits and per-tick step on the samples' phi (N,) [rad]."""
    low, high = float(gate.wrist_min_rad), float(gate.wrist_max_rad)  # type: ignore[arg-type]
    beyond = np.maximum(low - phi, phi - high)
    add(
        "wrist_limit",
        beyond > 1e-12,
        beyond,
        lambda v, _i: (
            f"the wrist up to {math.degrees(v):.2f} deg outside its limits "
            f"[{math.degrees(low):.1f}, {math.degrees(high):.1f}] deg"
        ),
    )
    step = np.concatenate([[0.0], np.abs(np.diff(phi))])
    limit = gate.wrist_max_step_rad
    add(
        "wrist_speed",
        step > limit + 1e-12,
        step / period_s,
        lambda v, _i: (
            f"the wrist turns at up to {v:.2f} rad/s, above its limit {limit / period_s:.2f} rad/s"
        ),
    )


def verify_path(
    gate: Gate,
    limits: VerifyLimits,
    times_s: np.ndarray,
    lines: np.ndarray,
    points_m: np.ndarray,
    velocity_m_s: np.ndarray,
    acceleration_m_s2: np.ndarray,
    near: np.ndarray,
    period_s: float,
    wrist: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> Verification:
    """Check samples (N,) times [s], lines, points (N, 3) [m], velocities (N, 3) [m/s],
    accelerations (N, 3) [m/s^2] at the loop's ``period_s`` [s], the loop starting from
    joints ``near`` (3,) [rad] (NaN: the knee-out branch at the first point); ``wrist``:
    with a wrist, phi (N,) [rad] and its first two derivatives (N,) [rad/s, rad/s^2] at
    the samples (None: phi = 0 throughout).

    Returns every violation (see module); raises nothing for a bad path.
    """
    robot = gate.robot
    # the program moves the tool tip: the checks are on the platform centre it implies
    # (see module); violations name the tip
    p, pd, pdd = _platform(gate, points_m, velocity_m_s, acceleration_m_s2, wrist)
    mm = 1e3
    found: list[Violation] = []

    def add(kind, bad, value, message):
        found.extend(_collect(kind, bad, value, lines, times_s, points_m, message))

    if wrist is not None and gate.wrist_min_rad is not None and gate.wrist_max_rad is not None:
        _check_wrist(gate, np.asarray(wrist[0], dtype=np.float64), period_s, add)

    inside = np.asarray(robot.reachable(p, margin=gate.margin_m), dtype=bool)
    add(
        "workspace",
        ~inside,
        np.zeros(len(p)),
        lambda _v, _i: f"outside the workspace (kept {gate.margin_m * mm:.1f} mm from its edge)",
    )
    over = p[:, 2] - gate.z_max_m
    add(
        "ceiling",
        over > 0,
        over,
        lambda v, _i: f"up to {v * mm:.2f} mm above the ceiling z = {gate.z_max_m * mm:.1f} mm",
    )
    joints, ok = follow_branch(robot, p, near)
    add("ik", ~ok, np.zeros(len(p)), lambda _v, _i: "no joint solution on the followed branch")

    low, high = np.asarray(gate.joint_min_rad), np.asarray(gate.joint_max_rad)
    with np.errstate(invalid="ignore"):
        beyond = np.maximum(low - joints, joints - high)  # > 0 outside, (N, 3)
    beyond = np.where(ok[:, None], beyond, -np.inf)
    worst_joint = np.argmax(beyond, axis=1)
    beyond_max = beyond[np.arange(len(p)), worst_joint]

    def limit_message(v: float, i: int) -> str:
        j = int(worst_joint[i])
        return (
            f"joint {j + 1} up to {math.degrees(v):.1f} deg outside its limits "
            f"[{math.degrees(low[j]):.1f}, {math.degrees(high[j]):.1f}] deg"
        )

    add("joint_limit", beyond_max > 0, beyond_max, limit_message)

    # the loop's own rule: the joint step from one tick to the next
    step = np.zeros(len(p))
    both = np.concatenate([[False], ok[1:] & ok[:-1]])
    step[both] = np.abs(np.diff(joints, axis=0)).max(axis=-1)[both[1:]]
    speed_limit = gate.max_step_rad / period_s
    add(
        "joint_speed",
        step > gate.max_step_rad + 1e-12,
        step / period_s,
        lambda v, _i: f"joint speed up to {v:.2f} rad/s, above the limit {speed_limit:.2f} rad/s",
    )

    good = np.flatnonzero(ok)
    qd = np.full_like(p, np.nan)
    qdd = np.full_like(p, np.nan)
    if good.size:
        qd[good] = robot.joint_velocity(joints[good], pd[good])
        qdd[good] = robot.joint_acceleration(joints[good], pd[good], pdd[good])
    accel = np.where(ok, np.nan_to_num(np.abs(qdd), nan=np.inf).max(axis=-1), 0.0)
    accel_limit = limits.joint_acceleration_rad_s2
    add(
        "joint_acceleration",
        accel > accel_limit,
        accel,
        lambda v, _i: (
            f"joint acceleration up to {v:.0f} rad/s^2, above the limit {accel_limit:.0f} rad/s^2"
        ),
    )

    dexterity = np.full(len(p), np.inf)
    if good.size:
        dexterity[good] = np.nan_to_num(robot.dexterity(joints[good]), nan=0.0)
    add(
        "singularity",
        dexterity < gate.min_dexterity,
        -dexterity,
        lambda v, _i: (
            f"too close to a singularity: 1/cond(J) down to {-v:.3f} (< {gate.min_dexterity})"
        ),
    )

    worst_ratio: float | None = None
    dynamics = dynamics_robot(robot)  # a per-leg robot's torques: its legs' mean (model.py)
    if limits.servo is not None and limits.mass is not None and isinstance(dynamics, RotaryDelta):
        ratio = np.zeros(len(p))
        torque = np.zeros_like(p)
        if good.size:
            with np.errstate(all="ignore"):
                tau = inverse_dynamics_joints(
                    dynamics, limits.mass, joints[good], qd[good], qdd[good]
                )
                available = limits.servo.torque_at(np.abs(qd[good]) * RPM_PER_RAD_S)
                r = np.abs(tau) / available
            r = np.nan_to_num(r, nan=np.inf, posinf=np.inf)
            ratio[good] = r.max(axis=-1)
            torque[good] = tau
        servo_name, cap = limits.servo.name, limits.max_torque_ratio
        add(
            "torque",
            ratio > cap,
            ratio,
            lambda v, _i: (
                f"torque up to {v:.2f} of what the {servo_name} gives at that "
                f"speed (limit {cap:.2f})"
                if math.isfinite(v)
                else f"torque needed at a joint speed where the {servo_name} gives none "
                f"(at or past its no-load speed; limit {cap:.2f} of what it gives)"
            ),
        )
        worst_ratio = float(ratio[good].max()) if good.size else math.nan  # inf: no torque left

    order = {kind: k for k, kind in enumerate(KINDS)}
    found.sort(key=lambda v: (v.t_s, order[v.kind]))
    has = good.size > 0
    return Verification(
        found,
        float(np.abs(qd[good]).max()) if has else math.nan,
        float(accel[good].max()) if has else math.nan,
        float(dexterity[good].min()) if has else math.nan,
        worst_ratio,
    )

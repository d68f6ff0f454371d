"""Every sample of a planned program through what the live loop checks, all violations.

The same limits as the gate (app/control/gate.py) and the run check
(app/runs/feasibility.py), on the samples the loop would command at its period, but
collected rather than raised at the first: per program line and kind of check, the first
offending sample (its time and point) and, in words, the worst value on that line, the
limit and by how much. :func:`fold` orders them by move, each line's first cause first
and the others folded under it (docs/gcode.md). Checks:

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
from dataclasses import dataclass, replace

import numpy as np

from app.control.branch import follow_branch
from app.control.gate import Gate
from app.control.model import dynamics_robot
from kinematics import RotaryDelta
from kinematics.dynamics import MassModel, inverse_dynamics_joints
from kinematics.sizing import RPM_PER_RAD_S, Servo
from kinematics.workspace import signed_distance

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


# A move's first cause (see fold): where the point is comes before what the joints' rates
# and the servo's torque do because of it; in each group, this order breaks a tie in time.
CAUSES = (
    "workspace",
    "ceiling",
    "ik",
    "joint_limit",
    "wrist_limit",
    "singularity",
    "wrist_speed",  # with a tool, the wrist's turn moves the platform: the joints follow it
    "joint_speed",
    "joint_acceleration",
    "torque",
)
RATES = frozenset({"joint_speed", "wrist_speed", "joint_acceleration", "torque"})


@dataclass(frozen=True)
class Violation:
    """One check failed on one program line: its first offending sample's time t_s [s]
    from the program's start and point_m (3,) [m, base frame]; message: what, in words
    (the line's worst value, the limit and by how much). folded_under: in a report's
    list (see :func:`fold`), the index of its move's first cause, under which it is
    folded; None for a first cause."""

    line: int
    kind: str
    message: str
    t_s: float
    point_m: tuple[float, float, float]
    folded_under: int | None = None


def fold(violations: list[Violation]) -> list[Violation]:
    """The violations by move, each move's first cause first, its others folded under it.

    A move is a program line. Its first cause: its earliest violation of where the point
    is (workspace, ceiling, ik, joint_limit, wrist_limit, singularity; a tie in time in
    that order); on a line with none of these, its earliest of the rates and the torque
    (wrist_speed, joint_speed, joint_acceleration, torque, in that order): a joint that
    races or a servo short of torque near a limit of position is its consequence, never
    its cause. The others of the line follow it by time (ties in the same order), each
    with ``folded_under`` the index of the first cause. A kind not of a move (run_duration:
    a program too long to run) is a first cause of its own. Moves in the order they
    start (lines do not go back in time). Returns a new list; the input is not changed.
    """
    order = {kind: k for k, kind in enumerate(CAUSES)}
    groups: dict[tuple[int, int], list[Violation]] = {}
    for k, v in enumerate(violations):
        key = (v.line, -1) if v.kind in order else (v.line, k)
        groups.setdefault(key, []).append(v)

    def cause(v: Violation) -> tuple[bool, float, int]:
        return (v.kind in RATES, v.t_s, order.get(v.kind, len(order)))

    def by_time(v: Violation) -> tuple[float, int]:
        return (v.t_s, order.get(v.kind, len(order)))

    out: list[Violation] = []
    for members in sorted(groups.values(), key=lambda g: min(by_time(v) for v in g)):
        first = min(members, key=cause)
        at = len(out)
        out.append(replace(first, folded_under=None))
        rest = sorted((v for v in members if v is not first), key=by_time)
        out.extend(replace(v, folded_under=at) for v in rest)
    return out


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
    """One Violation per line with a bad sample: its first one (time, point), and the
    message ``message(worst, w)`` of the line's worst value and the sample ``w`` it is at
    (the message names that sample's joint, value and limit).

    Lines do not decrease with time (a program runs forward), so each line's bad samples
    are one run of ``flatnonzero(bad)``.
    """
    index = np.flatnonzero(bad)
    if not index.size:
        return []
    bad_lines = lines[index]
    starts = np.flatnonzero(np.concatenate([[True], bad_lines[1:] != bad_lines[:-1]]))
    ends = [*starts[1:], len(index)]
    out = []
    for start, end in zip(starts, ends, strict=True):
        i = int(index[start])
        run = index[start:end]
        worst = int(run[np.argmax(value[run])])  # the first of equal worst values
        point = points[i]
        out.append(
            Violation(
                int(lines[i]),
                kind,
                message(float(value[worst]), worst),
                float(times[i]),
                (float(point[0]), float(point[1]), float(point[2])),
            )
        )
    return out


def _beyond(what: str, value_deg: float, excess_deg: float, low_deg: float, high_deg: float) -> str:
    """``what`` reaches its value, by how much past which limit [deg] (the human text)."""
    side, limit = ("upper", high_deg) if value_deg > high_deg else ("lower", low_deg)
    return (
        f"{what} reaches {value_deg:.1f} deg, {excess_deg:.1f} deg beyond its {side} "
        f"limit {limit:.1f} deg"
    )


def _workspace_message(outside_m: float, margin_m: float) -> str:
    """A point ``outside_m`` [m] past the workspace's edge (negative: inside it, but
    within the ``margin_m`` [m] the check keeps from it); NaN: not known."""
    mm = 1e3
    kept = f"the {margin_m * mm:.1f} mm kept inside its edge"
    if not math.isfinite(outside_m):
        return f"outside the workspace (kept {margin_m * mm:.1f} mm from its edge)"
    past = (outside_m + margin_m) * mm
    if outside_m >= 0:
        return f"{outside_m * mm:.1f} mm outside the workspace, {past:.1f} mm past {kept}"
    return f"{-outside_m * mm:.1f} mm inside the workspace's edge, {past:.1f} mm into {kept}"


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
    deg = math.degrees
    add(
        "wrist_limit",
        beyond > 1e-12,
        beyond,
        lambda v, i: _beyond("the wrist", deg(phi[i]), deg(v), deg(low), deg(high)),
    )
    step = np.concatenate([[0.0], np.abs(np.diff(phi))])
    limit = gate.wrist_max_step_rad
    speed_limit = limit / period_s
    add(
        "wrist_speed",
        step > limit + 1e-12,
        step / period_s,
        lambda v, _i: (
            f"the wrist turns at {v:.2f} rad/s, {v - speed_limit:.2f} rad/s over its limit "
            f"{speed_limit:.2f} rad/s"
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
    margin = gate.margin_m
    # for the words only: how far past the kept margin (the farthest leg's signed distance)
    edge = np.full(len(p), np.nan)
    if (~inside).any():
        edge[~inside] = signed_distance(robot, p[~inside])
    add(
        "workspace",
        ~inside,
        np.nan_to_num(edge + margin, nan=-np.inf),
        lambda v, _i: _workspace_message(v - margin, margin),
    )
    over = p[:, 2] - gate.z_max_m
    add(
        "ceiling",
        over > 0,
        over,
        lambda v, i: (
            f"the platform reaches z = {p[i, 2] * mm:.2f} mm, {v * mm:.2f} mm above the "
            f"ceiling z = {gate.z_max_m * mm:.1f} mm"
        ),
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
        deg = math.degrees
        return _beyond(f"joint {j + 1}", deg(joints[i, j]), deg(v), deg(low[j]), deg(high[j]))

    add("joint_limit", beyond_max > 0, beyond_max, limit_message)

    # the loop's own rule: the joint step from one tick to the next
    step = np.zeros(len(p))
    step_joint = np.zeros(len(p), dtype=int)
    both = np.concatenate([[False], ok[1:] & ok[:-1]])
    steps = np.abs(np.diff(joints, axis=0))
    step[both] = steps.max(axis=-1)[both[1:]]
    step_joint[both] = steps.argmax(axis=-1)[both[1:]]
    speed_limit = gate.max_step_rad / period_s
    add(
        "joint_speed",
        step > gate.max_step_rad + 1e-12,
        step / period_s,
        lambda v, i: (
            f"joint {step_joint[i] + 1} turns at {v:.2f} rad/s, {v - speed_limit:.2f} rad/s "
            f"over the speed limit {speed_limit:.2f} rad/s"
        ),
    )

    good = np.flatnonzero(ok)
    qd = np.full_like(p, np.nan)
    qdd = np.full_like(p, np.nan)
    if good.size:
        qd[good] = robot.joint_velocity(joints[good], pd[good])
        qdd[good] = robot.joint_acceleration(joints[good], pd[good], pdd[good])
    per_joint = np.nan_to_num(np.abs(qdd), nan=np.inf)
    accel = np.where(ok, per_joint.max(axis=-1), 0.0)
    accel_limit = limits.joint_acceleration_rad_s2

    def accel_message(v: float, i: int) -> str:
        j = int(np.argmax(per_joint[i])) + 1
        if not math.isfinite(v):
            return (
                f"joint {j}'s acceleration has no finite value here (the joint velocity "
                f"kinematics break down), over the limit {accel_limit:.0f} rad/s^2"
            )
        digits = 0 if accel_limit >= 10 else 2  # a small limit's excess in whole units is 0

        def num(x: float) -> str:
            return f"{x:.{digits}f}"

        return (
            f"joint {j} accelerates at {num(v)} rad/s^2, {num(v - accel_limit)} rad/s^2 over "
            f"the limit {num(accel_limit)} rad/s^2"
        )

    add("joint_acceleration", accel > accel_limit, accel, accel_message)

    dexterity = np.full(len(p), np.inf)
    if good.size:
        dexterity[good] = np.nan_to_num(robot.dexterity(joints[good]), nan=0.0)
    add(
        "singularity",
        dexterity < gate.min_dexterity,
        -dexterity,
        lambda v, _i: (
            f"too close to a singularity: 1/cond(J) down to {-v:.3f}, "
            f"{gate.min_dexterity + v:.3f} below the minimum {gate.min_dexterity}"
        ),
    )

    worst_ratio: float | None = None
    dynamics = dynamics_robot(robot)  # a per-leg robot's torques: its legs' mean (model.py)
    if limits.servo is not None and limits.mass is not None and isinstance(dynamics, RotaryDelta):
        ratio = np.zeros(len(p))
        ratios = np.zeros_like(p)  # per joint
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
            ratios[good] = r
            torque[good] = tau
        servo_name, cap = limits.servo.name, limits.max_torque_ratio
        add(
            "torque",
            ratio > cap,
            ratio,
            lambda v, i: (
                f"joint {int(np.argmax(ratios[i])) + 1} needs {v:.2f} of the torque the "
                f"{servo_name} gives at that speed, {v - cap:.2f} over the limit {cap:.2f}"
                if math.isfinite(v)
                else f"joint {int(np.argmax(ratios[i])) + 1} needs torque at a speed where "
                f"the {servo_name} gives none (at or past its no-load speed; limit {cap:.2f} "
                "of what it gives)"
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

"""Gains checked on the MuJoCo twin before they are offered (issue 21's goal), simulated time.

Four checks, each with a gain set per joint written to the three servo models (one set
for all, or one per joint in joint order; IK goals
streamed at 200 Hz as Goal Position ticks, the firmware's 1 ms period, the physics'
own time step; no wall clock, so the figures do not depend on the machine's load):

- `sinusoid`: the thesis's tracking test (ch. 6.1, Table 6.1): X, Y 5 cm at 1 Hz, Z 8 cm
  at 2 Hz about (0, 0, -0.24) m, in phase; the goals optionally commanded `lead_s` ahead
  (the loop's lead-time feed-forward, ``[runs] feedforward_lead_s``). RMSE per axis of the
  FK of the encoders against the reference [m], peak PWM and the share of servo periods
  with some joint's PWM at its limit.
- `step`: a 20 mm step of the goal in z from (0, 0, -0.24) m; the overshoot [%] of each
  joint's encoder beyond its step (the largest of the three), the step large enough
  (~50 ticks per joint) for one tick to be ~2 %.
- `rest`: from (0, 0, -0.24) m a 1 s minimum-jerk move to each of five points across the
  workspace (benchmarks/sag_at_rest.py's), then 1.5 s at rest; the true platform's
  distance from the goal [m].
- `long_move`: what an operator does next (issue 28): a 70 mm go-to from (0, 0, -0.24) m
  along x and down z, on the loop's own jerk-limited path at the jog limits (ruckig,
  `MoveSource`); the true platform's overshoot past the goal along the move [m] after
  the path ends, and the time [s] from the path's end until it stays within
  `Limits.settle_band_m` of the goal (an integral that winds up during the move shows
  here: the servo model clamps the integral term at the PWM limit, as the firmware's
  anti-windup).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from app.control.gravity import GravityOffset, loop_stiffness_nm_rad
from app.control.sources import Limits as PathLimits
from app.control.sources import MoveSource
from app.tuning.gains import Plant, Suggestion, Target, d_limit, suggest
from hardware.bus import PositionGains, per_joint
from hardware.dynamixel.control_table import RAD_PER_TICK
from hardware.shaft_motion import MotionCommand
from hardware.sim.twin import DeltaTwin, hold_command
from kinematics import THESIS_DELTA

RATE_HZ = 200
HOME_M = np.array([0.0, 0.0, -0.24])
STEP_M = np.array([0.0, 0.0, 0.02])
REST_POINTS_M = (
    (0.0, 0.0, -0.20),
    (0.06, 0.0, -0.24),
    (-0.04, 0.05, -0.22),
    (-0.03, -0.06, -0.27),
    (0.05, 0.05, -0.29),
)
LONG_MOVES_M = ((0.07, 0.0, -0.24), (0.0, 0.0, -0.31))  # 70 mm from HOME_M
# the jog limits' defaults (app/config.py [jog]): what a go-to runs at
GOTO_LIMITS = PathLimits(velocity=0.5, acceleration=4.0, jerk=100.0)
AT_LIMIT = 0.999  # a PWM at or above this fraction of the limit counts as saturated
JOINTS = (1, 2, 3)
FACTORY = PositionGains()  # the XM430's own gains (P 800, no I, D or feed-forward)

JointGains = tuple[PositionGains, PositionGains, PositionGains]
Gains = PositionGains | Sequence[PositionGains]


def joint_gains(gains: Gains) -> JointGains:
    """`gains` as one set per joint (1..3): a single set for all three, or three in joint
    order. Raises ValueError for a sequence of another length."""
    a, b, c = per_joint(gains, len(JOINTS))
    return a, b, c


def thesis_reference(t: float) -> np.ndarray:
    """The thesis sinusoid's point [m] at time t [s], X and Y in phase: shape (3,)."""
    w = 2.0 * math.pi
    return np.array(
        [0.05 * math.sin(w * t), 0.05 * math.sin(w * t), -0.24 + 0.08 * math.sin(2 * w * t)]
    )


NO_PROFILE = (0.0, 0.0)  # Profile Velocity and Acceleration 0: the goal is a step (the loop's)


def command(
    shaft_rad: float, gains: PositionGains, profile: tuple[float, float] = NO_PROFILE
) -> MotionCommand:
    """Hold `shaft_rad` [rad] with `gains` (all five registers) and the firmware's
    velocity-based `profile`: (Profile Velocity [rad/s], Profile Acceleration [rad/s^2]) of
    the shaft, 0 unlimited. The Feedforward 1st/2nd gains act on the Profile's velocity and
    acceleration (hardware/sim/xm430.py, the e-manual's position controller), so with no
    Profile they act on nothing."""
    return replace(
        hold_command(shaft_rad),
        position_p=gains.p,
        position_i=gains.i,
        position_d=gains.d,
        feedforward_1st=gains.feedforward_1st,
        feedforward_2nd=gains.feedforward_2nd,
        profile_velocity_rad_s=profile[0],
        profile_acceleration_rad_s2=profile[1],
    )


def _offset(gains: JointGains, on: bool) -> GravityOffset | None:
    """The loop's gravity offset under `gains` (``[control] gravity_compensation``): none
    where off; per joint, none where its gains have an integral (app/control/gravity.py's
    `loop_stiffness_nm_rad`)."""
    if not on or all(g.i > 0 for g in gains):
        return None
    return GravityOffset(THESIS_DELTA, stiffness_nm_rad=loop_stiffness_nm_rad(gains))


def _send(
    twin: DeltaTwin,
    joints: np.ndarray,
    gains: JointGains,
    offset: GravityOffset | None,
    profile: tuple[float, float] = NO_PROFILE,
) -> None:
    if offset is not None:
        joints = joints + offset.offset_rad(joints)
    ticks = np.round(twin.shafts_of_joints(joints) / RAD_PER_TICK)
    shafts = ticks * RAD_PER_TICK
    twin.set_commands([command(float(t), g, profile) for t, g in zip(shafts, gains, strict=True)])


def _encoder_joints(twin: DeltaTwin) -> np.ndarray:
    return twin.joints_of_shafts(np.round(twin.shaft_rad / RAD_PER_TICK) * RAD_PER_TICK)


def _per_tick(twin: DeltaTwin) -> int:
    return max(round(1.0 / RATE_HZ / twin.model.opt.timestep), 1)


@dataclass(frozen=True)
class Tracking:
    """The sinusoid's rmse_m [m] per axis (x, y, z), peak_pwm (fraction of the limit) and
    at_limit (share of the measured physics steps with some joint's PWM at its limit)."""

    rmse_m: tuple[float, float, float]
    peak_pwm: float
    at_limit: float


def sinusoid(
    gains: Gains,
    seconds: float = 3.0,
    lead_s: float = 0.0,
    warmup_s: float = 1.0,
    gravity: bool = False,
    profile: tuple[float, float] = NO_PROFILE,
) -> Tracking:
    """The thesis sinusoid tracked with `gains`, goals `lead_s` [s] ahead, measured over
    `seconds` [s] after `warmup_s` [s] (module docstring); `gravity`: the goals shifted by
    the loop's gravity offset where the gains have no integral; `profile`: the servos'
    velocity-based Profile (`command`; none, as the loop drives them, by default). Raises
    ValueError for a negative time or profile."""
    if min(seconds, lead_s, warmup_s) < 0 or seconds == 0:
        raise ValueError("seconds, lead_s, warmup_s: must be >= 0 (seconds > 0)")
    if min(profile) < 0:
        raise ValueError(f"profile = {profile}: velocity and acceleration must be >= 0")
    gains = joint_gains(gains)
    twin, robot = DeltaTwin(), THESIS_DELTA
    offset = _offset(gains, gravity)
    q = robot.ik(thesis_reference(lead_s)).joints
    twin.reset(robot.ik(thesis_reference(0.0)).joints)
    per_tick = _per_tick(twin)
    errors, peak, saturated, steps = [], 0.0, 0, 0
    for k in range(round((seconds + warmup_s) * RATE_HZ)):
        q = robot.ik(thesis_reference(k / RATE_HZ + lead_s), near=q).joints
        _send(twin, q, gains, offset, profile)
        for _ in range(per_tick):
            twin.step()
            if twin.time_s < warmup_s:
                continue
            point = robot.fk(_encoder_joints(twin)).points
            errors.append(point - thesis_reference(twin.time_s))
            pwm = max(abs(o.pwm) for o in twin.outputs) / twin.servos[0].params.pwm_limit
            peak = max(peak, pwm)
            saturated += pwm >= AT_LIMIT
            steps += 1
    rmse = np.sqrt(np.mean(np.square(errors), axis=0))
    return Tracking((float(rmse[0]), float(rmse[1]), float(rmse[2])), peak, saturated / steps)


def step(gains: Gains, duration_s: float = 1.5, gravity: bool = False) -> float:
    """The largest joint overshoot [%] of the 20 mm z step held `duration_s` [s]
    (module docstring); `gravity` as for `sinusoid`."""
    gains = joint_gains(gains)
    twin, robot = DeltaTwin(), THESIS_DELTA
    offset = _offset(gains, gravity)
    q0 = robot.ik(HOME_M).joints
    q1 = robot.ik(HOME_M + STEP_M, near=q0).joints
    if offset is not None:
        q0, q1 = q0 + offset.offset_rad(q0), q1 + offset.offset_rad(q1)
    twin.reset(q0)
    _send(twin, q0, gains, None)
    twin.advance(0.5)
    start = _encoder_joints(twin)
    _send(twin, q1, gains, None)
    goal = twin.joints_of_shafts(np.round(twin.shafts_of_joints(q1) / RAD_PER_TICK) * RAD_PER_TICK)
    size = goal - start
    worst = 0.0
    for _ in range(round(duration_s * 1000)):
        twin.step()
        moved = (_encoder_joints(twin) - start) / size
        worst = max(worst, float(moved.max()) - 1.0)
    return 100.0 * worst


def _blend(s: float) -> float:
    s = min(max(s, 0.0), 1.0)
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def rest(
    gains: Gains, move_s: float = 1.0, rest_s: float = 1.5, gravity: bool = False
) -> list[float]:
    """The true platform's distance [m] from each of the five goals after the move and the
    rest (module docstring): a list of 5; `gravity` as for `sinusoid`."""
    gains = joint_gains(gains)
    twin, robot = DeltaTwin(), THESIS_DELTA
    offset = _offset(gains, gravity)
    per_tick = _per_tick(twin)
    out = []
    for point in REST_POINTS_M:
        goal = np.array(point)
        q = robot.ik(HOME_M).joints
        twin.reset(q)
        for k in range(round((move_s + rest_s) * RATE_HZ) + 1):
            target = HOME_M + _blend(k / RATE_HZ / move_s) * (goal - HOME_M)
            q = robot.ik(target, near=q).joints
            _send(twin, q, gains, offset)
            twin.step(per_tick)
        out.append(float(np.linalg.norm(twin.platform_m - goal)))
    return out


@dataclass(frozen=True)
class LongMove:
    """The `long_move` figures per move (LONG_MOVES_M's order): overshoot_m [m] past the
    goal along the move after the path ends (0: none), settle_s [s] from the path's end
    until the platform stays within the band (`after_s` when it never does)."""

    overshoot_m: tuple[float, ...]
    settle_s: tuple[float, ...]


def long_move(
    gains: Gains,
    settle_band_m: float = 0.0007,
    after_s: float = 2.0,
    gravity: bool = False,
    goals_m: Sequence[Sequence[float]] = LONG_MOVES_M,
    limits: PathLimits = GOTO_LIMITS,
) -> LongMove:
    """Each 70 mm go-to of the module docstring with `gains`, watched `after_s` [s] after
    the path ends; `gravity` as for `sinusoid`. Raises ValueError for a band or a time
    <= 0."""
    if settle_band_m <= 0 or after_s <= 0:
        raise ValueError("settle_band_m, after_s: must be > 0")
    gains = joint_gains(gains)
    robot = THESIS_DELTA
    offset = _offset(gains, gravity)
    overshoots, settles = [], []
    for point in goals_m:
        twin = DeltaTwin()
        per_tick = _per_tick(twin)
        goal = np.asarray(point, dtype=np.float64)
        path = MoveSource(HOME_M, goal, limits, None, joint_space=False)
        q = robot.ik(HOME_M).joints
        twin.reset(q)
        _send(twin, q, gains, offset)
        twin.advance(0.5)
        along = (goal - HOME_M) / np.linalg.norm(goal - HOME_M)
        ticks = math.ceil(path.duration_s * RATE_HZ)
        past, outside_until = 0.0, 0.0
        for k in range(ticks + round(after_s * RATE_HZ)):
            q = robot.ik(path.next(1.0 / RATE_HZ).point_m, near=q).joints
            _send(twin, q, gains, offset)
            twin.step(per_tick)
            if k + 1 < ticks:
                continue
            since_end = (k + 1) / RATE_HZ - path.duration_s
            error = twin.platform_m - goal
            past = max(past, float(error @ along))
            if float(np.linalg.norm(error)) > settle_band_m:
                outside_until = min(max(since_end, 0.0) + 1.0 / RATE_HZ, after_s)
        overshoots.append(past)
        settles.append(outside_until)
    return LongMove(tuple(overshoots), tuple(settles))


@dataclass(frozen=True)
class Limits:
    """Issue 21's goal: RMSE x, y under rmse_xy_m [m], z under rmse_z_m [m] (half of thesis
    Table 6.1's 8.1 / 8.7 / 14.7 mm), PWM at its limit at most at_limit of the run, step
    overshoot at most overshoot_pct [%], error at rest under rest_m [m] at every point;
    issue 28's long move: overshoot past the goal at most long_overshoot_m [m], within
    settle_band_m [m] of the goal at most settle_s [s] after the path ends."""

    rmse_xy_m: float = 0.0040
    rmse_z_m: float = 0.0074
    at_limit: float = 0.01
    overshoot_pct: float = 5.0
    rest_m: float = 0.0002
    long_overshoot_m: float = 0.002
    settle_band_m: float = 0.0007
    settle_s: float = 0.5


@dataclass(frozen=True)
class Verdict:
    """The twin's figures for one gain set: the sinusoid without (`plain`) and with
    (`lead`) the loop's lead, the step's overshoot_pct [%], rest_m [m] at five points, and
    `failed`: the names of the limits it misses (empty: it passes), and the long move's
    figures (`long`: `LongMove`; none in a verdict made without it). `lead` and `plain`
    both must pass the PWM limit; the RMSE limits must hold for at least one of them (the
    loop runs with or without lead)."""

    plain: Tracking
    lead: Tracking
    lead_s: float
    overshoot_pct: float
    rest_m: tuple[float, ...]
    failed: tuple[str, ...]
    long: LongMove = LongMove((), ())

    @property
    def passes(self) -> bool:
        return not self.failed

    def as_dict(self) -> dict[str, object]:
        return asdict(self) | {"passes": self.passes}


def _tracking_fails(t: Tracking, limits: Limits) -> list[str]:
    x, y, z = t.rmse_m
    out = []
    if max(x, y) >= limits.rmse_xy_m:
        out.append("rmse_xy_m")
    if z >= limits.rmse_z_m:
        out.append("rmse_z_m")
    return out


def check(
    gains: Gains,
    lead_s: float = 0.02,
    seconds: float = 3.0,
    limits: Limits = Limits(),
    gravity: bool = False,
) -> Verdict:
    """All four checks of `gains` on the twin and the limits they miss (`Verdict`);
    `gravity`: with the loop's gravity offset (``[control] gravity_compensation``), which
    acts only where the gains have no integral. `gains`: one set for all joints, or one
    per joint."""
    plain = sinusoid(gains, seconds, gravity=gravity)
    lead = sinusoid(gains, seconds, lead_s, gravity=gravity)
    overshoot = step(gains, gravity=gravity)
    rest_m = tuple(rest(gains, gravity=gravity))
    long = long_move(gains, limits.settle_band_m, gravity=gravity)
    failed = []
    if _tracking_fails(plain, limits) and _tracking_fails(lead, limits):
        failed += _tracking_fails(lead, limits)
    if max(plain.at_limit, lead.at_limit) > limits.at_limit:
        failed.append("at_limit")
    if overshoot > limits.overshoot_pct:
        failed.append("overshoot_pct")
    if max(rest_m) >= limits.rest_m:
        failed.append("rest_m")
    if max(long.overshoot_m) > limits.long_overshoot_m:
        failed.append("long_overshoot_m")
    if max(long.settle_s) > limits.settle_s:
        failed.append("settle_s")
    return Verdict(plain, lead, lead_s, overshoot, rest_m, tuple(failed), long)


@dataclass(frozen=True)
class Candidate:
    """One gain set checked on the twin: the `target` variant the rule was given, the
    `gains` per joint (1..3; a joint not tuned keeps the gains it had), the twin's
    `verdict`, and the rule's `suggestions` per tuned joint (gains and the model's
    prediction of them)."""

    target: Target
    gains: JointGains
    verdict: Verdict
    suggestions: dict[int, Suggestion] = field(default_factory=dict)


@dataclass(frozen=True)
class Offer:
    """What the twin check offers: `tried`, every candidate checked, in order; `chosen`,
    the index of the one offered in it; `reason`, why that one (the first to pass every
    limit, or, when none did, the closest and what it misses)."""

    tried: tuple[Candidate, ...]
    chosen: int
    reason: str

    @property
    def candidate(self) -> Candidate:
        return self.tried[self.chosen]

    @property
    def gains(self) -> JointGains:
        return self.candidate.gains

    @property
    def target(self) -> Target:
        return self.candidate.target

    @property
    def verdict(self) -> Verdict:
        return self.candidate.verdict

    @property
    def met(self) -> bool:
        """Whether the offered gains pass every limit (issue 21's goal) on the twin."""
        return self.verdict.passes


# tighter and tighter D caps (gains.d_limit), down to none at 1.0
PWM_FRACTIONS = (0.8, 0.9, 0.95, 0.98, 0.99, 1.0)
# With no D the loop's damping is the fitted zeta's alone, a / (2 sqrt(g Kp)): the fit's
# least certain figure (wn, zeta and delay trade against each other, docs/performance.md),
# and the model's step then overshoots more than the twin's. There the model's overshoot
# allowance is widened this much in turn; the twin's own step still holds the real limit.
MODEL_SLACK = (1.0, 1.5, 2.0)


def excess(v: Verdict, limits: Limits = Limits()) -> float:
    """How far `v` misses its limits: the sum over the failed ones of figure / limit
    (RMSE: the better of plain and lead), 0 when it passes."""
    ratios = {
        "rmse_xy_m": min(max(t.rmse_m[:2]) for t in (v.plain, v.lead)) / limits.rmse_xy_m,
        "rmse_z_m": min(t.rmse_m[2] for t in (v.plain, v.lead)) / limits.rmse_z_m,
        "at_limit": max(v.plain.at_limit, v.lead.at_limit) / limits.at_limit,
        "overshoot_pct": v.overshoot_pct / limits.overshoot_pct,
        "rest_m": max(v.rest_m) / limits.rest_m,
        "long_overshoot_m": max(v.long.overshoot_m, default=0.0) / limits.long_overshoot_m,
        "settle_s": max(v.long.settle_s, default=0.0) / limits.settle_s,
    }
    return sum(ratios[name] for name in v.failed)


def _score(v: Verdict, limits: Limits) -> tuple[int, float]:
    return len(v.failed), excess(v, limits)


def variants(target: Target, gravity: bool = False) -> list[Target]:
    """The targets `offer` gives the rule, in order: a tighter and tighter tick-noise D cap
    (pwm_fraction in PWM_FRACTIONS at or above the target's; with no D, the model's
    overshoot allowance widened by MODEL_SLACK), each with the integral and, with
    `gravity` (the loop's gravity offset on), also without it (the offset then removes
    the sag)."""
    fractions = [f for f in PWM_FRACTIONS if f >= target.pwm_fraction] or [target.pwm_fraction]
    integrals = (True, False) if gravity else (target.integral,)
    out = []
    for fraction in fractions:
        slacks = MODEL_SLACK if d_limit(fraction) == 0 else (1.0,)
        for slack in slacks:
            overshoot = min(target.overshoot_pct * slack, 50.0)
            for integral in integrals:
                out.append(
                    replace(
                        target, pwm_fraction=fraction, integral=integral, overshoot_pct=overshoot
                    )
                )
    return out


def _plants(plant: Plant | Mapping[int, Plant]) -> dict[int, Plant]:
    plants = dict.fromkeys(JOINTS, plant) if isinstance(plant, Plant) else dict(plant)
    if not plants or not set(plants) <= set(JOINTS):
        raise ValueError(f"plants for joints {sorted(plants)}: one or more of {list(JOINTS)}")
    return plants


def offer(
    plant: Plant | Mapping[int, Plant],
    target: Target,
    lead_s: float = 0.02,
    seconds: float = 3.0,
    limits: Limits = Limits(),
    gravity: bool = False,
    current: Gains = FACTORY,
    check_fn: Callable[[JointGains, float, float, Limits, bool], Verdict] = check,
) -> Offer:
    """The first of `target`'s `variants` whose suggested gains pass every limit on the
    twin (`check_fn`, `check` by default); else the one missing the fewest limits, then
    the least `excess` over them, its verdict naming what it misses.

    `plant`: one plant for all three joints, or a plant per joint tuned (1..3); a joint
    without one keeps its `current` gains (one set for all, or one per joint). Each
    candidate is the rule's gains (`gains.suggest`) for every tuned joint under one
    variant, checked together on the twin; gain sets already tried are skipped. Raises
    ValueError for plants of joints other than 1..3 or none."""
    plants = _plants(plant)
    kept = joint_gains(current)
    tried: list[Candidate] = []
    for variant in variants(target, gravity):
        rule = {j: suggest(p, variant) for j, p in plants.items()}
        gains = joint_gains([rule[j].gains if j in rule else kept[j - 1] for j in JOINTS])
        if any(gains == c.gains for c in tried):
            continue
        verdict = check_fn(gains, lead_s, seconds, limits, gravity)
        tried.append(Candidate(variant, gains, verdict, rule))
        if verdict.passes:
            reason = (
                f"the first of {len(tried)} tried to pass every limit on the twin (tried in "
                "order: the rule's own target, then tighter D caps and, with no D, wider "
                "model overshoot allowances)"
            )
            return Offer(tuple(tried), len(tried) - 1, reason)
    best = min(range(len(tried)), key=lambda k: _score(tried[k].verdict, limits))
    v = tried[best].verdict
    reason = (
        f"no candidate met the goal: of {len(tried)} tried, this one misses the fewest "
        f"limits ({len(v.failed)}: {', '.join(v.failed)}), then by the least excess over "
        f"them ({excess(v, limits):.2f}); offered as the closest"
    )
    return Offer(tuple(tried), best, reason)


@dataclass(frozen=True)
class OfferJob:
    """Everything `offer` needs, picklable (a worker process runs it: `run_offer`): the
    `plants` per tuned joint, the joints' `current` gains, the `target`, and the check's
    conditions (the loop's `lead_s` [s], `seconds` [s] of sinusoid measured, `limits`,
    `gravity`: the loop's gravity offset on)."""

    plants: dict[int, Plant]
    target: Target
    current: JointGains = (FACTORY,) * 3
    lead_s: float = 0.02
    seconds: float = 3.0
    limits: Limits = field(default_factory=Limits)
    gravity: bool = False


def run_offer(job: OfferJob) -> Offer:
    """`offer` for `job` (a module-level function: what a worker process is handed)."""
    return offer(
        job.plants, job.target, job.lead_s, job.seconds, job.limits, job.gravity, job.current
    )

"""The tip's contact force from the servos' currents, with its 1-sigma error, each read.

Torques from currents: tau = Kt i per joint, i the Present Current signed in the joint's
direction (hardware.bus.JointState), Kt the servo model's torque constant. Then
kinematics.contact.tip_force: F = J^-T (tau - tau_model(q, qd, qdd, g)), tau_model the
thesis ch. 3.2 Lagrangian model with the loop's masses (THESIS_MASS, with the wrist and
payload as app/control/gravity.py), F the force the tip applies on the surface, base frame.

Error budget, per joint, 1 sigma, independent, mapped through J^-T (tip_force_covariance):

- Kt: 10 % of |tau| (`kt_rel_std`). Kt = stall torque / stall current (3.0 N m / 2.3 A =
  1.304 N m/A, ROBOTIS XM430-W210 datasheet at 12 V) is the twin's exact constant; on a
  real servo the torque-current curve is not a straight line through the stall point, the
  gearbox's efficiency varies with load, and ROBOTIS publishes no unit-to-unit spread. 10 %
  is an assumption (the order of the performance graph's departure from a line); a
  calibration against a known weight would replace it.
- Current quantum: Present Current counts 2.69 mA (e-manual), Kt 2.69 mA / sqrt(12) =
  1.0 mN m (uniform rounding). Real servos add current noise of a few counts (not here).
- Gearbox Coulomb friction: 0.02 N m (`friction_nm`; the twin's frictionloss, an estimate:
  ROBOTIS does not publish it). At rest its sign is unknown and it can hold any torque up to
  that level, so it is all uncertainty; moving (|qd| > `moving_rad_s`) it opposes the
  motion and is compensated (tau_model + f sign(qd)), its level still uncertain by
  `friction_moving_rel_std`.
- Current ripple while moving: 0.035 N m (`ripple_moving_nm`). The firmware's P loop on
  whole encoder ticks makes the motor current chatter from one 1 ms period to the next,
  and the rotor's inertia takes it up: on the twin the joints' acceleration scatters by
  ~6 rad/s^2 (1 sigma) about its 10 ms mean (30 mm, 1 Hz sinusoids), and the torque left
  after the model (commanded qdd) scatters by 0.032-0.036 N m per joint. It is not
  independent between joints: in a symmetric motion (along z) the three chatter together,
  and the error along the motion is up to sqrt(3) times the std given. Measured on the twin
  only; a real servo's Present Current ripple (its firmware's filtering is not published)
  should be measured the same way. At rest friction holds the shaft and there is none.
- Masses: 10 % of |tau_model| (`mass_rel_std`): the thesis's component masses (ch. 4.2)
  were not weighed on the built robot, and glue, screws and cables add.
- Inertia: the rotor's reflected inertia dominates upper_inertia_kgm2 and is uncertain by
  x3 (kinematics/dynamics.py), so 1 sigma = upper_inertia_kgm2 |qdd| (`inertia_rel_std`).

Acceleration is not measured: qdd = 0 unless the caller gives one (the commanded one). An
unmodelled acceleration costs (I + ...) qdd per joint, about 4.75e-3 N m per rad/s^2 of the
rotor alone (~0.05 N m at 10 rad/s^2, as much as the friction), mapped through J^-T; the
std does not include it (it cannot know the acceleration it was not given).

The same code runs on real servos; the twin has Kt and the masses exact, so its errors are
friction, the encoder's and current's quanta, and qdd.

Cost: the estimate runs every tick while a touch, a press or force-limited motion runs, so
one read is computed in Python floats (kinematics' ``*_floats`` helpers: FK, the legs'
frame, dexterity, the model's torques, J^-T and the covariance once each), ~40 us instead
of ~400 us through the array functions, which it equals to ~1e-14 relative
(tests/control/test_force.py); they answer where the float path declines (M singular).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hardware.bus import JointState
from hardware.dynamixel.control_table import AMPERE_PER_CURRENT_UNIT
from kinematics import RotaryDelta
from kinematics.contact import (
    _joint_to_tip_force_floats,
    _tip_force_covariance_floats,
    joint_to_tip_force,
    tip_force_covariance,
)
from kinematics.differential import (
    _dexterity_floats,
    _jacobian_floats,
    _leg_frame_floats,
    dexterity,
)
from kinematics.dynamics import (
    STANDARD_GRAVITY,
    THESIS_MASS,
    MassModel,
    _inverse_dynamics_floats,
    inverse_dynamics_joints,
)

# XM430-W210 at 12 V, ROBOTIS datasheet: stall torque 3.0 N m at stall current 2.3 A. The
# same numbers as hardware.sim.xm430.XM430_W210 (tests/control/test_force.py holds them
# equal); not imported from there because hardware.sim loads MuJoCo, which the control loop
# on real servos does not need.
STALL_TORQUE_NM = 3.0
STALL_CURRENT_A = 2.3
TORQUE_CONSTANT_NM_A = STALL_TORQUE_NM / STALL_CURRENT_A
"""Output torque per motor current [N m/A] of the XM430-W210 (1.304), gearbox included."""
GEARBOX_FRICTION_NM = 0.02
"""Gearbox Coulomb friction at the output [N m] (an estimate; the twin's frictionloss)."""


@dataclass(frozen=True)
class ForceErrorBudget:
    """The 1-sigma error sources of the estimate (module doc for each one's source).

    kt_rel_std: relative error of Kt [1]; current_quantum_a: Present Current's unit [A];
    friction_nm: gearbox Coulomb friction [N m]; friction_moving_rel_std: relative error of
    the friction's level once compensated while moving [1]; moving_rad_s: joint speed
    above which friction's sign is taken as known [rad/s]; ripple_moving_nm: the torque's
    ripple while moving [N m]; mass_rel_std: relative error of
    the model's torques [1]; inertia_rel_std: relative error of the upper inertia [1].
    """

    kt_rel_std: float = 0.10
    current_quantum_a: float = AMPERE_PER_CURRENT_UNIT
    friction_nm: float = GEARBOX_FRICTION_NM
    friction_moving_rel_std: float = 0.5
    moving_rad_s: float = 0.05
    ripple_moving_nm: float = 0.035
    mass_rel_std: float = 0.10
    inertia_rel_std: float = 1.0

    def __post_init__(self) -> None:
        for name in (
            "kt_rel_std",
            "current_quantum_a",
            "friction_nm",
            "friction_moving_rel_std",
            "moving_rad_s",
            "ripple_moving_nm",
            "mass_rel_std",
            "inertia_rel_std",
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} = {value!r}: must be finite and >= 0")


def _nan3() -> np.ndarray:
    return np.full(3, np.nan)


@dataclass(frozen=True)
class ForceEstimate:
    """The tip's contact force from one read.

    force_n: the force the tip applies on the surface [N] (3,), base frame (pressing down
    on a plate below: force_n[2] < 0); std_n: its 1-sigma error per axis [N] (3,);
    covariance_n2: the full covariance [N^2] (3, 3) (the error along a direction n is
    sqrt(n . C n)); valid: False when no estimate could be made (then the arrays are NaN);
    reason: why not (None when valid).
    """

    force_n: np.ndarray = field(default_factory=_nan3)
    std_n: np.ndarray = field(default_factory=_nan3)
    valid: bool = False
    reason: str | None = None
    covariance_n2: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))

    @property
    def magnitude_n(self) -> float:
        """|force_n| [N] (NaN when not valid)."""
        return float(np.linalg.norm(self.force_n))


def _invalid(reason: str) -> ForceEstimate:
    return ForceEstimate(reason=reason)


_OUT_OF_REACH = "joints out of the model's reach (no forward kinematics)"
_NOT_FINITE = "the model gave no finite force at these joints"


def _too_near(dexterity_value: float, minimum: float) -> str:
    return f"too near a singularity: dexterity {dexterity_value:.3f} below {minimum:g}"


def _vector(value: Any, name: str) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} = {value!r}: expected three numbers") from exc
    if array.shape != (3,) or not np.isfinite(array).all():
        raise ValueError(f"{name} = {value!r}: expected three finite numbers")
    return array


_Triple = tuple[float, float, float]


def _triple(value: Any, name: str) -> _Triple:
    """:func:`_vector` as three Python floats, without NumPy for a tuple, list or (3,)
    array of finite numbers (the tick's case); the same errors otherwise."""
    if isinstance(value, (tuple, list, np.ndarray)) and len(value) == 3:
        items = value.tolist() if isinstance(value, np.ndarray) else value
        try:
            out = (float(items[0]), float(items[1]), float(items[2]))
        except (TypeError, ValueError):
            out = None
        if out is not None and all(math.isfinite(x) for x in out):
            return out
    a, b, c = _vector(value, name).tolist()
    return a, b, c


def _first_three(values: Any) -> _Triple:
    a, b, c = np.asarray(values[:3], dtype=float).tolist()
    return a, b, c


class ForceEstimator:
    """Turns a read of the legs (`JointState`) into the tip's contact force.

    robot: the rotary Delta (the calibrated geometry when there is one); mass: the loop's
    mass model (payload and wrist included, `force_estimator` builds it like
    gravity_offset); torque_constant_nm_a: Kt [N m/A]; budget: the error sources;
    min_dexterity: below this the Jacobian is too near a singularity to invert (the force
    per torque grows without bound), the estimate is refused.

    Raises TypeError for a robot that is not a RotaryDelta, ValueError for a Kt that is
    not finite and > 0 or a min_dexterity outside [0, 1).
    """

    def __init__(
        self,
        robot: RotaryDelta,
        mass: MassModel = THESIS_MASS,
        torque_constant_nm_a: float = TORQUE_CONSTANT_NM_A,
        budget: ForceErrorBudget | None = None,
        min_dexterity: float = 0.05,
    ) -> None:
        if not isinstance(robot, RotaryDelta):
            raise TypeError(f"a force estimate needs a RotaryDelta, got {type(robot).__name__}")
        if not isinstance(mass, MassModel):
            raise TypeError(f"mass: expected a MassModel, got {type(mass).__name__}")
        if not (math.isfinite(torque_constant_nm_a) and torque_constant_nm_a > 0):
            raise ValueError(f"torque_constant_nm_a = {torque_constant_nm_a!r}: must be > 0")
        if not 0.0 <= min_dexterity < 1.0:
            raise ValueError(f"min_dexterity = {min_dexterity!r}: must be within [0, 1)")
        self.robot = robot
        self.mass = mass
        self.kt = float(torque_constant_nm_a)
        self.budget = budget or ForceErrorBudget()
        self.min_dexterity = float(min_dexterity)

    def with_robot(self, robot: RotaryDelta) -> ForceEstimator:
        """The same estimator on ``robot`` (a calibration's geometry); TypeError for a
        robot that is not a RotaryDelta."""
        return ForceEstimator(robot, self.mass, self.kt, self.budget, self.min_dexterity)

    def torques_nm(self, current_a: Any) -> np.ndarray:
        """Joint torques [N m] (3,) of currents [A] (3,), signed in the joints' direction."""
        return self.kt * np.asarray(current_a, dtype=float)

    def torque_std_nm(
        self,
        measured_nm: np.ndarray,
        model_nm: np.ndarray,
        qd: np.ndarray,
        qdd: np.ndarray,
    ) -> np.ndarray:
        """Each joint's 1-sigma torque error [N m] (3,) (the budget, module doc), for the
        measured torques, the model's (friction excluded), speeds and accelerations."""
        b = self.budget
        moving = np.abs(qd) > b.moving_rad_s
        friction = np.where(moving, b.friction_moving_rel_std, 1.0) * b.friction_nm
        terms = (
            b.kt_rel_std * np.abs(measured_nm),
            np.full(3, self.kt * b.current_quantum_a / math.sqrt(12.0)),
            friction,
            np.where(moving, b.ripple_moving_nm, 0.0),
            b.mass_rel_std * np.abs(model_nm),
            b.inertia_rel_std * self.mass.upper_inertia_kgm2 * np.abs(qdd),
        )
        return np.sqrt(sum(t * t for t in terms))

    def estimate(
        self, joints: JointState, gravity: Any = STANDARD_GRAVITY, qdd: Any = None
    ) -> ForceEstimate:
        """The contact force at this read.

        Args:
            joints: the read; its first three joints are the legs (a wrist's is ignored:
                it turns about z and loads no leg motor).
            gravity: gravity in the base frame [m/s^2] (3,) (a tilted drone's, rotated).
            qdd: the legs' joint acceleration [rad/s^2] (3,) when known (the commanded
                one); None: taken as zero (module doc for the cost while moving).

        Returns:
            ForceEstimate; valid False with a reason for a current or position not read,
            a joint with torque off or in a hardware fault, or joints the model cannot
            take (out of reach, too near a singularity).

        Raises:
            ValueError: fewer than three joints, or gravity / qdd not three finite numbers.
        """
        g = _triple(gravity, "gravity")
        acc = (0.0, 0.0, 0.0) if qdd is None else _triple(qdd, "qdd")
        if len(joints.position_rad) < 3:
            raise ValueError(
                f"a force estimate needs the three legs, got {len(joints.position_rad)} joints"
            )
        q = _first_three(joints.position_rad)
        qd = _first_three(joints.velocity_rad_s)
        current = _first_three(joints.current_a)
        for k in range(3):
            if not math.isfinite(current[k]):
                return _invalid(f"current of joint {k + 1} not read")
            if not (math.isfinite(q[k]) and math.isfinite(qd[k])):
                return _invalid(f"position or velocity of joint {k + 1} not read")
            if joints.torque_enabled is not None and not joints.torque_enabled[k]:
                return _invalid(f"torque off on joint {k + 1}: its current holds nothing")
            if joints.hardware_errors[k]:
                errors = ", ".join(joints.hardware_errors[k])
                return _invalid(f"joint {k + 1} in a hardware fault ({errors})")
        fast = self._estimate_floats(q, qd, current, g, acc)
        if fast is not None:
            return fast
        return self._estimate_arrays(
            np.array(q), np.array(qd), np.array(current), np.array(g), np.array(acc)
        )

    def _estimate_arrays(
        self, q: np.ndarray, qd: np.ndarray, current: np.ndarray, g: np.ndarray, acc: np.ndarray
    ) -> ForceEstimate:
        """The estimate of checked reads (3,) with the kinematics' array functions: the
        reference :meth:`_estimate_floats` equals, and the answer where it gives none."""
        d = float(dexterity(self.robot, q))
        if not math.isfinite(d):
            return _invalid(_OUT_OF_REACH)
        if d < self.min_dexterity:
            return _invalid(_too_near(d, self.min_dexterity))
        measured = self.torques_nm(current)
        b = self.budget
        friction = np.where(np.abs(qd) > b.moving_rad_s, np.sign(qd) * b.friction_nm, 0.0)
        # F = J^-T (tau - tau_model) (kinematics.contact.tip_force), with the model's
        # torques kept for the budget; what overcomes friction is no contact force
        model = inverse_dynamics_joints(self.robot, self.mass, q, qd, acc, g)
        force = joint_to_tip_force(self.robot, q, measured - friction - model)
        std = self.torque_std_nm(measured, model, qd, acc)
        cov = tip_force_covariance(self.robot, q, std)
        if not (np.isfinite(force).all() and np.isfinite(cov).all()):
            return _invalid(_NOT_FINITE)
        return ForceEstimate(force, np.sqrt(np.diag(cov)), True, None, cov)

    def _estimate_floats(
        self, q: _Triple, qd: _Triple, current: _Triple, g: _Triple, acc: _Triple
    ) -> ForceEstimate | None:
        """:meth:`_estimate_arrays` in Python floats, each step the same formula (the
        tick's path, ~8x cheaper: NumPy's per-call overhead on (3,) arrays dwarfs the
        arithmetic); None where M is singular or a value is not finite (an overflow),
        for the array path to answer."""
        frame = _leg_frame_floats(self.robot, q)
        if frame is None:
            return None if self.robot.fk(q).ok else _invalid(_OUT_OF_REACH)
        d = _dexterity_floats(_jacobian_floats(frame))
        if not math.isfinite(d):
            return _invalid(_OUT_OF_REACH)
        if d < self.min_dexterity:
            return _invalid(_too_near(d, self.min_dexterity))
        b = self.budget
        measured = [self.kt * c for c in current]
        model = _inverse_dynamics_floats(self.mass, frame, qd, acc, g)
        friction = [math.copysign(b.friction_nm, v) if abs(v) > b.moving_rad_s else 0.0 for v in qd]
        residual = [measured[i] - friction[i] - model[i] for i in range(3)]
        force = _joint_to_tip_force_floats(frame, (residual[0], residual[1], residual[2]))
        std = self._torque_std_floats(measured, model, qd, acc)
        cov = _tip_force_covariance_floats(frame, std)
        if not all(math.isfinite(x) for x in (*force, *cov[0], *cov[1], *cov[2])):
            return _invalid(_NOT_FINITE)
        spread = np.array([math.sqrt(cov[0][0]), math.sqrt(cov[1][1]), math.sqrt(cov[2][2])])
        return ForceEstimate(np.array(force), spread, True, None, np.array(cov))

    def _torque_std_floats(
        self, measured: list[float], model: _Triple, qd: _Triple, qdd: _Triple
    ) -> _Triple:
        """:meth:`torque_std_nm` in Python floats, term by term."""
        b = self.budget
        quantum = self.kt * b.current_quantum_a / math.sqrt(12.0)
        out = []
        for k in range(3):
            moving = abs(qd[k]) > b.moving_rad_s
            terms = (
                b.kt_rel_std * abs(measured[k]),
                quantum,
                (b.friction_moving_rel_std if moving else 1.0) * b.friction_nm,
                b.ripple_moving_nm if moving else 0.0,
                b.mass_rel_std * abs(model[k]),
                b.inertia_rel_std * self.mass.upper_inertia_kgm2 * abs(qdd[k]),
            )
            out.append(math.sqrt(sum(t * t for t in terms)))
        return out[0], out[1], out[2]


def force_estimator(
    robot: object,
    payload_kg: float = 0.0,
    wrist: bool = False,
    budget: ForceErrorBudget | None = None,
) -> ForceEstimator:
    """The estimator for `robot` with the thesis masses (THESIS_MASS), `payload_kg` [kg] on
    the platform and, with `wrist`, an XM430 wrist on it, as app/control/gravity.py's
    `gravity_offset` builds the loop's model.

    Raises ValueError for a robot that is not a rotary Delta (a linear Delta's rails need
    their own dynamics model).
    """
    if not isinstance(robot, RotaryDelta):
        raise ValueError("contact force estimate: only rotary Deltas have a dynamics model")
    mass = THESIS_MASS.with_wrist() if wrist else THESIS_MASS
    return ForceEstimator(robot, mass.with_payload(payload_kg), budget=budget)

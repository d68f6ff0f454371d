"""Inverse dynamics of the rotary Delta: Lagrange's equations with multipliers (ch. 3.2).

Generalized coordinates Q = (P, theta) (eq. 3.106), three constraints
Gamma_i = |P - C_i(theta_i)|^2 - l^2 = 0 (eq. 3.104), C_i the shifted knee. Bodies:

- platform: point mass m_P at P (payload included), K = m_P |Pd|^2 / 2 (eq. 3.92);
- upper link i: inertia I about the motor axis (rotor included), K = I qd_i^2 / 2
  (eq. 3.93); its centre of mass halfway along L, as eq. 3.101 assumes;
- lower link i: both rods and their joints, a uniform rod from knee to platform joint,
  K = m_L / 6 (|vC|^2 + vC . vP + |vP|^2) (the garbled eq. 3.94-3.99), potential energy
  at its midpoint (eq. 3.102).

Gravity is any vector g in the base frame (the drone tilts), U = -sum m g . x_com.
Worked out in vector form with C' = dC/dq, C'' = d2C/dq2 and the knee acceleration
aC = C' qdd + C'' qd^2, the equations for P (eq. 3.122-3.124) give the multipliers:

    m_P a + m_L/6 sum(aC_i + 2 a) - (m_P + 3 m_L / 2) g = sum 2 lambda_i (P - C_i)

and eq. 3.113-3.125 give the torques (positive in the direction of positive theta):

    tau_i = I qdd_i + m_L/6 C_i' . (2 aC_i + a) - (m_U + m_L)/2 g . C_i'
            + 2 lambda_i (P - C_i) . C_i'

The vector form needs no per-leg partial derivatives, so the printed slips (eq. 3.119's
sin(theta_1) for sin(theta_2), the garbled eq. 3.113) cannot enter. Pure NumPy,
vectorized over (*, 3) samples; no I/O.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ._arrays import as_vectors
from ._xp import LEG_COS, LEG_SIN
from .differential import _inverse_rows, _jacobian_floats, _LegFrameFloats
from .errors import InvalidGeometryError
from .rotary import RotaryDelta

_RADIAL = np.array([[c, s, 0.0] for c, s in zip(LEG_COS, LEG_SIN, strict=True)])

STANDARD_GRAVITY = (0.0, 0.0, -9.81)
"""Gravity in the base frame of a level drone [m/s^2]."""


@dataclass(frozen=True)
class MassModel:
    """Masses and inertia of a rotary Delta (thesis eq. 3.92-3.102).

    Attributes:
        platform_kg: moving platform with tool and payload [kg], > 0.
        upper_kg: one upper link [kg], >= 0; its centre of mass at L/2.
        upper_inertia_kgm2: one upper link about the motor axis, plus the motor's rotor
            reflected through the gearbox [kg m^2], >= 0.
        lower_kg: one leg's whole lower link (both rods and their four ball joints)
            [kg], >= 0; modelled as a uniform rod from knee to platform joint.
    """

    platform_kg: float
    upper_kg: float
    upper_inertia_kgm2: float
    lower_kg: float

    def __post_init__(self) -> None:
        for name in ("platform_kg", "upper_kg", "upper_inertia_kgm2", "lower_kg"):
            value = getattr(self, name)
            number = isinstance(value, numbers.Real) and not isinstance(value, bool)
            finite = number and math.isfinite(value)
            if not (finite and (value > 0.0 if name == "platform_kg" else value >= 0.0)):
                bound = "> 0" if name == "platform_kg" else ">= 0"
                raise InvalidGeometryError(f"{name} = {value!r}: must be finite and {bound}")

    def with_payload(self, payload_kg: float) -> MassModel:
        """The same robot with ``payload_kg`` [kg] added to the platform."""
        return MassModel(
            self.platform_kg + payload_kg, self.upper_kg, self.upper_inertia_kgm2, self.lower_kg
        )

    def with_wrist(self, wrist: WristMasses | None = None) -> MassModel:
        """The same robot with a wrist on the platform (default `WRIST_XM430`): its servo
        and turning part add to the platform's mass. The translational dynamics do not see
        the wrist's own inertia (it turns about z on a platform that does not turn)."""
        w = WRIST_XM430 if wrist is None else wrist
        return self.with_payload(w.servo_kg + w.turning_kg)


# Thesis ch. 4.2 masses. The upper link (29 g nylon) about the motor axis as a uniform
# rod, m L^2 / 3 = 2.35e-4 kg m^2 at L = 0.1558 m. The rotor dominates: the XM430-W210's
# 212.6:1 gearbox reflects a ~1.0e-7 kg m^2 coreless rotor (typical of its 17 mm motor;
# Robotis publishes no figure) as 212.6^2 * 1e-7 = 4.52e-3 kg m^2. Total 4.75e-3, the
# same order as hardware.shaft_motion's 5e-3 plant. A system-identified armature (MuJoCo
# Menagerie OP3, XM430-W350: 0.045 kg m^2, i.e. 0.016 at the W210's ratio) is larger:
# treat the rotor term as uncertain by x3 when sizing for acceleration.
_UPPER_LINK_KG = 0.029
_ROTOR_REFLECTED_KGM2 = 212.6**2 * 1.0e-7

THESIS_MASS = MassModel(
    platform_kg=0.025,  # nylon platform without payload
    upper_kg=_UPPER_LINK_KG,
    upper_inertia_kgm2=_UPPER_LINK_KG * 0.1558**2 / 3.0 + _ROTOR_REFLECTED_KGM2,
    lower_kg=2 * 0.0105,  # two CFRP rods, each 3.5 g plus two 3.5 g ball joints
)
"""The thesis robot's mass model without payload; ``THESIS_MASS.with_payload(0.2)`` is
the sizing case (max payload 0.2 kg, ch. 4 design goals)."""


@dataclass(frozen=True)
class WristMasses:
    """A wrist's masses: servo_kg, the servo's case (bolted to the platform, moves with
    it, does not turn); turning_kg and turning_inertia_kgm2, the horn and tool turning
    with the wrist (inertia about the wrist's axis, at the output, without the rotor's
    reflected inertia, which hardware/sim adds as the joint's armature like the legs')."""

    servo_kg: float
    turning_kg: float
    turning_inertia_kgm2: float


# An XM430-W210 as the wrist: 82 g (ROBOTIS e-Manual, XM430-W210 specifications: "Weight
# 82 g"; the smaller XL430-W250 is 57.2 g). Turning: a 20 g horn and tool, taken as a
# uniform disc of 20 mm radius, I = m r^2 / 2 = 4.0e-6 kg m^2. The rotor's inertia
# reflected through the 212.6:1 gearbox (4.5e-3 kg m^2, hardware/sim/masses.py)
# dominates the wrist's own by a thousand times.
WRIST_XM430 = WristMasses(servo_kg=0.082, turning_kg=0.020, turning_inertia_kgm2=4.0e-6)


class JointMotion(NamedTuple):
    """Joint positions [rad], speeds [rad/s] and accelerations [rad/s^2], each (*, 3)."""

    joints: np.ndarray
    speeds: np.ndarray
    accelerations: np.ndarray


def joint_motion(robot: RotaryDelta, p: Any, pd: Any, pdd: Any) -> JointMotion:
    """Joint motion for a platform motion (inverse position, velocity, acceleration).

    Args:
        p, pd, pdd: platform position [m], velocity [m/s], acceleration [m/s^2] in the
            base frame, each broadcastable to (*, 3).

    Returns:
        JointMotion; NaN rows where ``p`` is out of reach.
    """
    p, pd, pdd = np.broadcast_arrays(
        as_vectors(p, "p"), as_vectors(pd, "pd"), as_vectors(pdd, "pdd")
    )
    q = robot.ik(p).joints
    return JointMotion(q, robot.joint_velocity(q, pd), robot.joint_acceleration(q, pd, pdd))


def _knee_derivatives(robot: RotaryDelta, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """dC_i/dq_i and d2C_i/dq_i^2, each (*, 3 legs, 3) [m/rad, m/rad^2]."""
    derivs = [robot._leg_centre_derivatives(i, q[..., i]) for i in range(3)]
    first = np.stack([np.stack(d[0], -1) for d in derivs], axis=-2)
    second = np.stack([np.stack(d[1], -1) for d in derivs], axis=-2)
    return first, second


def _check(robot: Any, mass: Any) -> None:
    if not isinstance(robot, RotaryDelta):
        raise TypeError(f"dynamics model is for a RotaryDelta, got {type(robot).__name__}")
    if not isinstance(mass, MassModel):
        raise TypeError(f"mass: expected a MassModel, got {type(mass).__name__}")


def _torques(
    robot: RotaryDelta,
    mass: MassModel,
    p: np.ndarray,
    pdd: np.ndarray,
    motion: JointMotion,
    gravity: np.ndarray,
) -> np.ndarray:
    """Torques from a consistent platform and joint motion (the equations above)."""
    q, qd, qdd = motion
    c1, c2 = _knee_derivatives(robot, q)
    knee_acc = c1 * qdd[..., None] + c2 * (qd**2)[..., None]  # (*, 3 legs, 3)
    w = p[..., None, :] - robot.knees(q)  # P - C_i, rows of the constraint gradient / 2
    m_p, m_u, inertia, m_l = (
        mass.platform_kg,
        mass.upper_kg,
        mass.upper_inertia_kgm2,
        mass.lower_kg,
    )
    # sum_i m_L/6 (aC_i + 2 a) = m_L/6 sum_i aC_i + m_L a
    platform_force = (
        m_p * pdd + m_l * (knee_acc.sum(axis=-2) / 6.0 + pdd) - (m_p + 1.5 * m_l) * gravity
    )
    with np.errstate(all="ignore"):
        # 2 W^T lambda = platform_force with W's rows w_i: lambda = W^-T f / 2. The adjugate
        # inverse gives inf/NaN at a parallel singularity instead of raising.
        w_inv = _inverse_rows(w)
        lam = 0.5 * np.einsum("...ji,...j->...i", w_inv, platform_force)
    along = np.einsum("...ij,...ij->...i", c1, w)  # (P - C_i) . C_i'
    inertial = np.einsum("...ij,...ij->...i", c1, 2.0 * knee_acc + pdd[..., None, :])
    weight = np.einsum("...ij,...j->...i", c1, np.broadcast_to(gravity, p.shape))
    return inertia * qdd + m_l / 6.0 * inertial - 0.5 * (m_u + m_l) * weight + 2.0 * lam * along


def _gravity(gravity: Any) -> np.ndarray:
    g = as_vectors(gravity, "gravity")
    if not np.isfinite(g).all():
        raise InvalidGeometryError(f"gravity = {g.tolist()!r}: must be finite [m/s^2]")
    return g


def inverse_dynamics(
    robot: RotaryDelta, mass: MassModel, p: Any, pd: Any, pdd: Any, gravity: Any = STANDARD_GRAVITY
) -> np.ndarray:
    """Actuation torques for a platform motion (thesis eq. 3.89-3.125).

    Args:
        robot: a RotaryDelta.
        mass: its MassModel.
        p, pd, pdd: platform position [m], velocity [m/s], acceleration [m/s^2] in the
            base frame, each broadcastable to (*, 3).
        gravity: gravity in the base frame [m/s^2], broadcastable to (*, 3); a tilted
            drone sees it rotated.

    Returns:
        torques [N m], shape (*, 3), positive in the direction of positive theta (so
        holding a load against -z gravity takes negative torques). NaN where ``p`` is out
        of reach; inf/NaN at a singularity.
    """
    _check(robot, mass)
    g = _gravity(gravity)
    p, pd, pdd, g = np.broadcast_arrays(
        as_vectors(p, "p"), as_vectors(pd, "pd"), as_vectors(pdd, "pdd"), g
    )
    motion = joint_motion(robot, p, pd, pdd)
    return _torques(robot, mass, p, pdd, motion, g)


def inverse_dynamics_joints(
    robot: RotaryDelta, mass: MassModel, q: Any, qd: Any, qdd: Any, gravity: Any = STANDARD_GRAVITY
) -> np.ndarray:
    """Actuation torques for a joint motion [rad, rad/s, rad/s^2], each (*, 3) -> (*, 3) [N m].

    Same model as :func:`inverse_dynamics`; the platform's motion comes from forward
    kinematics: W a = V qdd - |Pd - C' qd|^2 + (W . C'') qd^2 (differential.py, solved
    for a).
    """
    _check(robot, mass)
    g = _gravity(gravity)
    q, qd, qdd, g = np.broadcast_arrays(
        as_vectors(q, "q"), as_vectors(qd, "qd"), as_vectors(qdd, "qdd"), g
    )
    p = robot.fk(q).points
    pd = robot.point_velocity(q, qd)
    c1, c2 = _knee_derivatives(robot, q)
    w = p[..., None, :] - robot.knees(q)
    with np.errstate(all="ignore"):
        relative = pd[..., None, :] - c1 * qd[..., None]
        rhs = (
            np.einsum("...ij,...ij->...i", w, c1) * qdd
            - np.einsum("...ij,...ij->...i", relative, relative)
            + np.einsum("...ij,...ij->...i", w, c2) * qd**2
        )
        pdd = np.einsum("...ij,...j->...i", _inverse_rows(w), rhs)
    return _torques(robot, mass, p, pdd, JointMotion(q, qd, qdd), g)


def _inverse_dynamics_floats(
    mass: MassModel,
    frame: _LegFrameFloats,
    qd: tuple[float, float, float],
    qdd: tuple[float, float, float],
    gravity: tuple[float, float, float],
) -> tuple[float, float, float]:
    """:func:`inverse_dynamics_joints` of one sample in Python floats [N m], from the legs'
    frame at its q (differential._leg_frame_floats), speeds [rad/s], accelerations
    [rad/s^2] and gravity [m/s^2]: the same steps, no per-call NumPy overhead (the
    control tick's contact force estimate). Finite inputs and frame assumed (not checked)."""
    w, c1, c2, v = frame.w, frame.d1, frame.d2, frame.v
    adj, det = frame.adjugate, frame.det
    jac = _jacobian_floats(frame)
    pd = [jac[i][0] * qd[0] + jac[i][1] * qd[1] + jac[i][2] * qd[2] for i in range(3)]
    rhs = []
    for i in range(3):
        rel = [pd[k] - c1[i][k] * qd[i] for k in range(3)]
        wc2 = w[i][0] * c2[i][0] + w[i][1] * c2[i][1] + w[i][2] * c2[i][2]
        rel2 = rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2]
        rhs.append(v[i] * qdd[i] - rel2 + wc2 * qd[i] ** 2)
    w_inv = [[adj[i][j] / det for j in range(3)] for i in range(3)]  # M^-1, rows
    pdd = [w_inv[i][0] * rhs[0] + w_inv[i][1] * rhs[1] + w_inv[i][2] * rhs[2] for i in range(3)]
    knee_acc = [[c1[i][k] * qdd[i] + c2[i][k] * qd[i] ** 2 for k in range(3)] for i in range(3)]
    m_p, m_u, inertia, m_l = mass.platform_kg, mass.upper_kg, mass.upper_inertia_kgm2, mass.lower_kg
    force = [
        m_p * pdd[k]
        + m_l * ((knee_acc[0][k] + knee_acc[1][k] + knee_acc[2][k]) / 6.0 + pdd[k])
        - (m_p + 1.5 * m_l) * gravity[k]
        for k in range(3)
    ]
    torques = []
    for i in range(3):
        # lambda_i = (W^-T f)_i / 2; along = (P - C_i) . C_i' = v_i
        lam = 0.5 * (w_inv[0][i] * force[0] + w_inv[1][i] * force[1] + w_inv[2][i] * force[2])
        a = c1[i]
        inertial = sum(a[k] * (2.0 * knee_acc[i][k] + pdd[k]) for k in range(3))
        weight = a[0] * gravity[0] + a[1] * gravity[1] + a[2] * gravity[2]
        torques.append(
            inertia * qdd[i] + m_l / 6.0 * inertial - 0.5 * (m_u + m_l) * weight + 2.0 * lam * v[i]
        )
    return torques[0], torques[1], torques[2]


class Energy(NamedTuple):
    """Kinetic and potential energy of the model [J], each shape (*)."""

    kinetic: np.ndarray
    potential: np.ndarray


def energy(
    robot: RotaryDelta, mass: MassModel, q: Any, qd: Any, gravity: Any = STANDARD_GRAVITY
) -> Energy:
    """Kinetic and potential energy at joints ``q`` [rad] and speeds ``qd`` [rad/s], (*, 3).

    Written from the body list above, independently of the torque formula, so that
    the work-energy law checks one against the other. Potential energy is relative to
    every centre of mass in the plane z = 0 (level drone), i.e. defined up to a constant.
    """
    _check(robot, mass)
    g = _gravity(gravity)
    q, qd = np.broadcast_arrays(as_vectors(q, "q"), as_vectors(qd, "qd"))
    p = robot.fk(q).points
    vp = robot.point_velocity(q, qd)
    c1, _ = _knee_derivatives(robot, q)
    vc = c1 * qd[..., None]
    knees = robot.knees(q)
    rod = (vc * vc).sum(-1) + (vc * vp[..., None, :]).sum(-1) + (vp * vp).sum(-1)[..., None]
    kinetic = (
        0.5 * mass.platform_kg * (vp * vp).sum(-1)
        + (0.5 * mass.upper_inertia_kgm2 * qd**2).sum(-1)
        + (mass.lower_kg / 6.0 * rod).sum(-1)
    )
    # centres of mass up to constants: upper link at hip + (C_i - Rbar e_i)/2, the lower
    # link at the midpoint of its shifted ends (C_i + P)/2
    upper = 0.5 * (knees + robot.Rbar * _RADIAL)
    lower = 0.5 * (knees + p[..., None, :])
    heights = mass.platform_kg * p + mass.upper_kg * upper.sum(-2) + mass.lower_kg * lower.sum(-2)
    potential = -(heights * g).sum(-1)
    return Energy(kinetic, potential)

"""The force the tool tip applies on its surroundings, from the joint torques (ch. 3.2).

With a force F [N] applied BY the tip ON the environment (base frame), the environment
pushes the platform with -F, and virtual work (pd = J qd, differential.py) puts -J^T F on
the joints. The motors then supply what the free arm needs plus the contact's share:

    tau_measured = tau_model(q, qd, qdd, g) + J^T F                      (1)

tau_model the inverse dynamics of the thesis's Lagrangian model (eq. 3.89-3.125,
dynamics.inverse_dynamics_joints). Hence

    F = J^-T (tau_measured - tau_model)                                   (2)

J = M^-1 V (differential.py: M's rows w_i = P - C_i, V = diag(w_i . C_i')), so
J^-T = M^T V^-1 needs no inverse at all: F = sum_i w_i (tau_i - tau_model_i) / v_i, each
leg's rod pushing along itself. Independent torque errors of standard deviation s_i [N m]
map to the covariance

    Cov F = J^-T diag(s^2) J^-1 = M^T diag(s^2 / v^2) M                   (3)

A pure moment on the platform loads no motor (the parallelograms carry it), so only the
force is observable: a tip off the platform centre gives the same F. Pure NumPy, vectorised
over (*, 3) like dynamics.py; no I/O. The control tick's one sample has a float twin of
eq. 2 and 3 (``_joint_to_tip_force_floats``, ``_tip_force_covariance_floats``, on
differential._leg_frame_floats): NumPy's per-call overhead on (3,) arrays costs ten times
the arithmetic (app/control/force.py).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._arrays import as_vectors
from .differential import _leg_frame, _LegFrameFloats
from .dynamics import STANDARD_GRAVITY, MassModel, _check, inverse_dynamics_joints
from .errors import NonFiniteError
from .rotary import RotaryDelta

__all__ = ["joint_to_tip_force", "tip_force", "tip_force_covariance"]


def _finite_or_nan(values: np.ndarray, axes: tuple[int, ...]) -> np.ndarray:
    """``values`` with every sample that holds an inf or NaN set wholly to NaN."""
    ok = np.isfinite(values).all(axis=axes)
    return np.where(np.expand_dims(ok, axes), values, np.nan)


def tip_force(
    robot: RotaryDelta,
    mass: MassModel,
    q: Any,
    qd: Any,
    qdd: Any,
    torques_nm: Any,
    gravity: Any = STANDARD_GRAVITY,
) -> np.ndarray:
    """The force the tip applies on the environment, from the motors' torques (eq. 2 above).

    Args:
        robot: a RotaryDelta (the calibrated geometry when there is one).
        mass: its MassModel (payload and wrist included, as the control loop's).
        q, qd, qdd: joint angles [rad], speeds [rad/s], accelerations [rad/s^2], each
            broadcastable to (*, 3).
        torques_nm: the motors' torques [N m], (*, 3), positive towards positive theta
            (the link down), as dynamics.inverse_dynamics_joints.
        gravity: gravity in the base frame [m/s^2], broadcastable to (*, 3) (a tilted drone).

    Returns:
        F [N], shape (*, 3), base frame: the force the tip exerts on what it touches (the
        tip pressing down on a plate below gives F[2] < 0). A NaN row where ``q`` is out of
        reach, at a singularity (serial: a v_i = 0; parallel: the model's W singular), or
        where any input of that row is NaN. Near a singularity F grows without bound: gate
        on dexterity.

    Raises:
        TypeError: ``robot`` is not a RotaryDelta or ``mass`` not a MassModel.
        ShapeError: an argument is not numbers shaped (..., 3).
        InvalidGeometryError: ``gravity`` is not finite.
    """
    _check(robot, mass)
    q, qd, qdd, tau = np.broadcast_arrays(
        as_vectors(q, "q"),
        as_vectors(qd, "qd"),
        as_vectors(qdd, "qdd"),
        as_vectors(torques_nm, "torques_nm"),
    )
    model = inverse_dynamics_joints(robot, mass, q, qd, qdd, gravity)
    return joint_to_tip_force(robot, q, tau - model)


def joint_to_tip_force(robot: RotaryDelta, q: Any, torques_nm: Any) -> np.ndarray:
    """F = J^-T tau = M^T V^-1 tau: the tip force [N] (*, 3) that joint torques [N m]
    (*, 3) balance at joints ``q`` [rad] (*, 3), e.g. the torques left after the model's.

    NaN rows where ``q`` is out of reach, at a serial singularity or for NaN input.
    Raises TypeError for a robot that is not a RotaryDelta, ShapeError for bad shapes.
    """
    if not isinstance(robot, RotaryDelta):
        raise TypeError(f"contact model is for a RotaryDelta, got {type(robot).__name__}")
    q, tau = np.broadcast_arrays(as_vectors(q, "q"), as_vectors(torques_nm, "torques_nm"))
    frame = _leg_frame(robot, q)
    with np.errstate(all="ignore"):
        per_leg = tau / frame.v  # V^-1 tau, (*, 3)
        force = np.einsum("...ij,...i->...j", frame.w, per_leg)  # M^T (...)
    return _finite_or_nan(force, (-1,))


def tip_force_covariance(robot: RotaryDelta, q: Any, torque_std_nm: Any) -> np.ndarray:
    """Covariance of :func:`tip_force` from independent joint torque errors (eq. 3 above).

    Args:
        robot: a RotaryDelta.
        q: joint angles [rad], (*, 3).
        torque_std_nm: each joint's torque error, one standard deviation [N m], >= 0,
            broadcastable to (*, 3) (a scalar triple for all samples, or one per sample).

    Returns:
        Cov F [N^2], shape (*, 3, 3), symmetric positive semi-definite; its diagonal's
        square roots are the 1-sigma errors of F's components. NaN where ``q`` is out of
        reach or at a singularity.

    Raises:
        TypeError: ``robot`` is not a RotaryDelta.
        ShapeError: an argument is not numbers shaped (..., 3).
        NonFiniteError: a ``torque_std_nm`` is negative, NaN or infinite.
    """
    if not isinstance(robot, RotaryDelta):
        raise TypeError(f"contact model is for a RotaryDelta, got {type(robot).__name__}")
    s = as_vectors(torque_std_nm, "torque_std_nm")
    if not (np.isfinite(s).all() and (s >= 0).all()):
        raise NonFiniteError(f"torque_std_nm = {s.tolist()!r}: must be finite and >= 0 [N m]")
    q, s = np.broadcast_arrays(as_vectors(q, "q"), s)
    frame = _leg_frame(robot, q)
    with np.errstate(all="ignore"):
        scaled = frame.w * (s / frame.v)[..., None]  # rows s_i w_i / v_i = (S V^-1 M)_i
        cov = np.einsum("...ki,...kj->...ij", scaled, scaled)
    return _finite_or_nan(cov, (-2, -1))


def _joint_to_tip_force_floats(
    frame: _LegFrameFloats, torques_nm: tuple[float, float, float]
) -> tuple[float, float, float]:
    """:func:`joint_to_tip_force` of one sample in floats: F = M^T V^-1 tau [N] from the
    legs' frame at q (differential._leg_frame_floats) and torques [N m]."""
    w, v = frame.w, frame.v
    per_leg = [torques_nm[i] / v[i] for i in range(3)]
    force = [w[0][k] * per_leg[0] + w[1][k] * per_leg[1] + w[2][k] * per_leg[2] for k in range(3)]
    return force[0], force[1], force[2]


def _tip_force_covariance_floats(
    frame: _LegFrameFloats, torque_std_nm: tuple[float, float, float]
) -> list[list[float]]:
    """:func:`tip_force_covariance` of one sample in floats: M^T diag(s^2 / v^2) M [N^2]
    (3 x 3 rows) from the legs' frame at q and torque errors s [N m] (>= 0, unchecked)."""
    w, v = frame.w, frame.v
    scaled = [[w[i][k] * (torque_std_nm[i] / v[i]) for k in range(3)] for i in range(3)]
    return [
        [
            scaled[0][a] * scaled[0][b] + scaled[1][a] * scaled[1][b] + scaled[2][a] * scaled[2][b]
            for b in range(3)
        ]
        for a in range(3)
    ]

"""Velocity and acceleration kinematics, and the distance to singularity.

Each leg keeps |P - C_i(q_i)| = l. Differentiating once (thesis eq. 3.59-3.68):

    (P - C_i) . dP = (P - C_i) . C_i'(q_i) dq_i      i.e.  M dP = V dq,  J = M^-1 V

with M's rows w_i = P - C_i and V = diag(w_i . C_i'). Differentiating twice
(thesis eq. 3.71-3.88, written without the local frames):

    w_i . C_i' qdd_i = w_i . Pdd + |Pd - C_i' qd_i|^2 - (w_i . C_i'') qd_i^2

Inverse velocity and acceleration need no matrix inverse; the Jacobian inverts M
with its adjugate, so a singular M gives inf/NaN instead of an exception.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from ._arrays import as_vectors, is_scalar_triple, triple_floats
from ._xp import FLOATS


class _LegFrame(NamedTuple):
    w: np.ndarray  # rows of M: P - C_i, shape (*, 3 legs, 3)
    d1: np.ndarray  # dC_i/dq_i, (*, 3, 3)
    d2: np.ndarray  # d2C_i/dq_i^2, (*, 3, 3)
    v: np.ndarray  # diagonal of V: w_i . d1_i, (*, 3)


def _leg_frame(robot: Any, joints: Any) -> _LegFrame:
    q = as_vectors(joints, "joints")
    points = robot.fk(q).points
    with np.errstate(all="ignore"):
        w = points[..., None, :] - robot.knees(q)
        derivs = [robot._leg_centre_derivatives(i, q[..., i]) for i in range(3)]
        d1 = np.stack([np.stack(d[0], -1) for d in derivs], axis=-2)
        d2 = np.stack([np.stack(d[1], -1) for d in derivs], axis=-2)
        return _LegFrame(w, d1, d2, np.einsum("...ij,...ij->...i", w, d1))


def _inverse_rows(m: np.ndarray) -> np.ndarray:
    """Inverse of a batch of 3x3 matrices from their rows (adjugate / determinant)."""
    r0, r1, r2 = m[..., 0, :], m[..., 1, :], m[..., 2, :]
    adj = np.stack([np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)], axis=-1)
    det = np.einsum("...i,...i->...", r0, adj[..., :, 0])
    return adj / det[..., None, None]


def jacobian(robot: Any, joints: Any) -> np.ndarray:
    """dP/dq: platform velocity per joint velocity, shape (*, 3, 3) [m/rad or m/m].

    NaN where FK fails; inf/NaN at a parallel (M) singularity.
    """
    if is_scalar_triple(joints):  # the control loop's case, every tick: floats, no stacking
        single = _jacobian_single(robot, triple_floats(joints, "joints"))
        if single is not None:
            return single
    frame = _leg_frame(robot, joints)
    with np.errstate(all="ignore"):
        return _inverse_rows(frame.w) * frame.v[..., None, :]


def _jacobian_single(robot: Any, q: tuple[float, float, float]) -> np.ndarray | None:
    """jacobian() of one joint triple in Python floats; None where the array path must
    answer (FK fails, M singular), so both paths give the same NaN/inf there."""
    point = robot.fk(q).points
    if not np.isfinite(point).all():
        return None
    rows, speeds = [], []
    for leg in range(3):
        centre = robot._leg_centre(leg, q[leg], FLOATS)
        first, _ = robot._leg_centre_derivatives(leg, q[leg])
        w = [float(p) - c for p, c in zip(point, centre, strict=True)]
        rows.append(w)
        speeds.append(sum(a * float(b) for a, b in zip(w, first, strict=True)))
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = rows
    # columns of M's adjugate: r1 x r2, r2 x r0, r0 x r1
    adjugate = (
        (b1 * c2 - b2 * c1, c1 * a2 - c2 * a1, a1 * b2 - a2 * b1),
        (b2 * c0 - b0 * c2, c2 * a0 - c0 * a2, a2 * b0 - a0 * b2),
        (b0 * c1 - b1 * c0, c0 * a1 - c1 * a0, a0 * b1 - a1 * b0),
    )
    det = a0 * adjugate[0][0] + a1 * adjugate[1][0] + a2 * adjugate[2][0]
    if det == 0.0:
        return None
    return np.array([[adjugate[i][j] / det * speeds[j] for j in range(3)] for i in range(3)])


_Triple = tuple[float, float, float]
_Rows = tuple[_Triple, _Triple, _Triple]


class _LegFrameFloats(NamedTuple):
    """_LegFrame of one joint triple in Python floats, with P and M's inverse (the
    contact force estimate's per-tick path, kinematics/contact.py)."""

    point: _Triple  # P = FK(q) [m]
    w: _Rows  # rows of M: P - C_i
    d1: _Rows  # dC_i/dq_i
    d2: _Rows  # d2C_i/dq_i^2
    v: _Triple  # diagonal of V: w_i . d1_i
    adjugate: _Rows  # M's adjugate, [i][j] = (w_j+1 x w_j+2)[i]: M^-1 = adjugate / det
    det: float  # det M


def _leg_frame_floats(robot: Any, q: _Triple) -> _LegFrameFloats | None:
    """_leg_frame of one joint triple (floats) as :func:`_jacobian_single` computes it;
    None where FK fails, M is singular or a value is not finite (the array path answers)."""
    point = robot.fk(q).points.tolist()
    if not all(math.isfinite(p) for p in point):
        return None
    w, d1, d2 = [], [], []
    for leg in range(3):
        centre = robot._leg_centre(leg, q[leg], FLOATS)
        first, second = robot._leg_centre_derivatives(leg, q[leg])
        w.append((point[0] - centre[0], point[1] - centre[1], point[2] - centre[2]))
        d1.append((float(first[0]), float(first[1]), float(first[2])))
        d2.append((float(second[0]), float(second[1]), float(second[2])))
    v = [r[0] * f[0] + r[1] * f[1] + r[2] * f[2] for r, f in zip(w, d1, strict=True)]
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = w
    adjugate = (
        (b1 * c2 - b2 * c1, c1 * a2 - c2 * a1, a1 * b2 - a2 * b1),
        (b2 * c0 - b0 * c2, c2 * a0 - c0 * a2, a2 * b0 - a0 * b2),
        (b0 * c1 - b1 * c0, c0 * a1 - c1 * a0, a0 * b1 - a1 * b0),
    )
    det = a0 * adjugate[0][0] + a1 * adjugate[1][0] + a2 * adjugate[2][0]
    # one sum is finite iff every term is (or it overflows: then the array path answers)
    total = sum(v) + det + sum(d1[0]) + sum(d1[1]) + sum(d1[2]) + sum(d2[0]) + sum(d2[1])
    if det == 0.0 or not math.isfinite(total + sum(d2[2])):
        return None
    return _LegFrameFloats(
        (point[0], point[1], point[2]),
        (w[0], w[1], w[2]),
        (d1[0], d1[1], d1[2]),
        (d2[0], d2[1], d2[2]),
        (v[0], v[1], v[2]),
        adjugate,
        det,
    )


def _jacobian_floats(frame: _LegFrameFloats) -> list[list[float]]:
    """J = M^-1 V of a float frame, [i][j] = dP_i/dq_j, as :func:`_jacobian_single`."""
    adjugate, det, speeds = frame.adjugate, frame.det, frame.v
    return [[adjugate[i][j] / det * speeds[j] for j in range(3)] for i in range(3)]


def _dexterity_floats(jac: list[list[float]]) -> float:
    """:func:`dexterity` of one Jacobian from :func:`_jacobian_floats`: its singular
    values' ratio, 0 where it is not finite (as the array path gives where FK holds)."""
    if not all(math.isfinite(x) for row in jac for x in row):
        return 0.0
    singular_values = np.linalg.svd(np.array(jac), compute_uv=False)
    return float(singular_values[-1] / singular_values[0])


def joint_velocity(robot: Any, joints: Any, point_velocity: Any) -> np.ndarray:
    """Inverse velocity kinematics (thesis eq. 3.70): joint speeds for a platform velocity.

    Args:
        joints: current joints, shape (*, 3).
        point_velocity: platform velocity in the base frame [m/s], shape (*, 3).

    Returns:
        joint velocities [rad/s or m/s], shape (*, 3).
    """
    frame = _leg_frame(robot, joints)
    pd = as_vectors(point_velocity, "point_velocity")
    with np.errstate(all="ignore"):
        return np.einsum("...ij,...j->...i", frame.w, pd) / frame.v


def point_velocity(robot: Any, joints: Any, joint_velocity: Any) -> np.ndarray:
    """Forward velocity kinematics: platform velocity [m/s] for joint speeds, shape (*, 3)."""
    qd = as_vectors(joint_velocity, "joint_velocity")
    return np.einsum("...ij,...j->...i", jacobian(robot, joints), qd)


def joint_acceleration(
    robot: Any, joints: Any, point_velocity: Any, point_acceleration: Any
) -> np.ndarray:
    """Inverse acceleration kinematics (thesis eq. 3.88).

    Args:
        joints: current joints, shape (*, 3).
        point_velocity: platform velocity [m/s], shape (*, 3).
        point_acceleration: platform acceleration [m/s^2], shape (*, 3).

    Returns:
        joint accelerations [rad/s^2 or m/s^2], shape (*, 3).
    """
    frame = _leg_frame(robot, joints)
    pd = as_vectors(point_velocity, "point_velocity")
    pdd = as_vectors(point_acceleration, "point_acceleration")
    with np.errstate(all="ignore"):
        qd = np.einsum("...ij,...j->...i", frame.w, pd) / frame.v
        relative = pd[..., None, :] - frame.d1 * qd[..., None]
        numerator = (
            np.einsum("...ij,...j->...i", frame.w, pdd)
            + np.einsum("...ij,...ij->...i", relative, relative)
            - np.einsum("...ij,...ij->...i", frame.w, frame.d2) * qd**2
        )
        return numerator / frame.v


def dexterity(robot: Any, joints: Any) -> np.ndarray | np.float64:
    """Inverse condition number of the Jacobian, shape (*): 1 isotropic, 0 singular.

    Serial singularities (a leg stretched or folded) and parallel ones (M singular)
    both drive it to 0, so one threshold keeps the loop away from either. NaN where FK
    fails.
    """
    jac = jacobian(robot, joints)
    if jac.shape == (3, 3) and np.isfinite(jac).all():  # one triple: skip the masking
        singular_values = np.linalg.svd(jac, compute_uv=False)
        return np.float64(singular_values[-1] / singular_values[0])
    finite = np.isfinite(jac).all(axis=(-2, -1))
    safe = np.where(finite[..., None, None], jac, np.eye(3))
    singular_values = np.linalg.svd(safe, compute_uv=False)
    with np.errstate(all="ignore"):
        ratio = singular_values[..., -1] / singular_values[..., 0]
    ratio = np.where(np.isfinite(ratio), ratio, 0.0)
    fk_ok = robot.fk(joints).ok
    return np.where(finite, ratio, np.where(fk_ok, 0.0, np.nan))

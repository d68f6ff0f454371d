"""Plan a calibration's poses and fit the model to the pairs they give.

Measurement model (kinematics/identification.py, eq. 1): y = Rm^T (FK(q; p) - tm). The
fit is ``scipy.optimize.least_squares`` with a robust loss (soft L1) inside the
identification's physical bounds, of:

- ``parameters="offsets"``: the three joint offsets o_i and the measurement frame (6-DoF);
- ``parameters="geometry"``: also each leg's L, l and R (R - r is all the model sees, so r
  stays nominal).

The frame is always free: where the motion capture sits is never known to a tenth of a
millimetre. The *current* model is the nominal one (what the controller uses now) with
only the frame fitted; a fit is offered only when its RMSE on held-out poses is below the
current model's there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from kinematics.identification import (
    Identification,
    MeasurementFrame,
    Observability,
    candidate_poses,
    select_poses,
)
from kinematics.per_leg import PerLegRotaryDelta

Parameters = Literal["offsets", "geometry"]
FRAME = ("frame_position", "frame_rotation")
GROUPS: dict[str, tuple[str, ...]] = {
    "offsets": ("offsets", *FRAME),
    "geometry": ("offsets", "L", "l", "R", *FRAME),
}
MIN_HOLDOUT = 3
HOLDOUT_FRACTION = 0.25
MIN_POSES = 12  # at least as many training equations as free parameters, with margin


class CalibrationError(ValueError):
    """Calibration input that cannot be used (too few poses, bad data); names the field."""


def identification(
    nominal: PerLegRotaryDelta, parameters: str, frame: MeasurementFrame | None = None
) -> Identification:
    """The identification of ``parameters`` ("offsets" or "geometry") about ``nominal``.

    Raises:
        CalibrationError: for another ``parameters``.
    """
    if parameters not in GROUPS:
        raise CalibrationError(f"parameters: {parameters!r} is not one of {sorted(GROUPS)}")
    return Identification(nominal, frame or MeasurementFrame(), GROUPS[parameters])


def holdout_count(poses: int) -> int:
    """How many of ``poses`` are held out for validation: a quarter, at least 3."""
    return max(MIN_HOLDOUT, round(HOLDOUT_FRACTION * poses))


@dataclass(frozen=True)
class Plan:
    """The poses of a calibration and what they can tell, before anything moves.

    fit_joints (N - H, 3) [rad]: D-optimal poses (``select_poses``) for the fit;
    holdout_joints (H, 3) [rad]: poses drawn at random from the same safe candidates, for
    validation only; observability: of the fit poses at the nominal model.
    """

    fit_joints: np.ndarray
    holdout_joints: np.ndarray
    observability: Observability

    @property
    def joints(self) -> np.ndarray:
        """Every pose in the order visited (fit poses, then held-out ones), (N, 3) [rad]."""
        return np.vstack([self.fit_joints, self.holdout_joints])


def plan(
    nominal: PerLegRotaryDelta,
    poses: int,
    parameters: str = "offsets",
    allowed: Any = None,
    seed: int = 0,
) -> Plan:
    """Choose ``poses`` joint sets: D-optimal fit poses plus random held-out ones.

    allowed: optional predicate over candidate joints (M, 3) -> bool mask (M,), e.g. the
    controller's joint limits and workspace; candidates failing it are never visited.

    Raises:
        CalibrationError: fewer than ``MIN_POSES`` poses, or too few safe candidates.
    """
    if poses < MIN_POSES:
        raise CalibrationError(f"poses: {poses} is too few (at least {MIN_POSES})")
    ident = identification(nominal, parameters)
    candidates = candidate_poses(nominal, seed=seed)
    if allowed is not None:
        candidates = candidates[np.asarray(allowed(candidates), dtype=bool)]
    holdout = holdout_count(poses)
    if len(candidates) < poses + holdout:
        raise CalibrationError(
            f"poses: {poses} asked, only {len(candidates)} safe candidate poses in reach"
        )
    fit_joints = select_poses(ident, poses - holdout, candidates=candidates)
    chosen = {tuple(q) for q in fit_joints}
    rest = np.array([q for q in candidates if tuple(q) not in chosen])
    picks = np.random.default_rng(seed + 1).choice(len(rest), holdout, replace=False)
    return Plan(fit_joints, rest[picks], ident.observability(ident.initial, fit_joints))


def rmse(residuals: Any) -> float:
    """Root mean square of the 3D distance between model and measurement [m], from the
    flattened (3N,) residual vector: sqrt(mean_k |e_k|^2)."""
    e = np.asarray(residuals, dtype=float).reshape(-1, 3)
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1)))) if len(e) else math.nan


@dataclass(frozen=True)
class FitResult:
    """A fit and its validation. Lengths in m, angles in rad.

    robot: the fitted per-leg model; frame: the fitted measurement frame.
    rmse_before_m / rmse_after_m: on the fit poses, current model (frame fitted) / new fit.
    holdout_before_m / holdout_rmse_m: the same on the held-out poses.
    better: the new fit is better than the current model on the held-out poses.
    residuals_before / residuals_after: (N, 3) [m] per pose (fit poses then held-out).
    """

    parameters: str
    robot: PerLegRotaryDelta
    frame: MeasurementFrame
    rmse_before_m: float
    rmse_after_m: float
    holdout_before_m: float
    holdout_rmse_m: float
    observability: Observability
    residuals_before: np.ndarray = field(repr=False)
    residuals_after: np.ndarray = field(repr=False)
    holdout: int = 0

    @property
    def better(self) -> bool:
        return bool(self.holdout_rmse_m < self.holdout_before_m)

    def parameters_out(self) -> dict[str, list[float]]:
        """The API's ``parameters`` object: joint offsets [rad] and each leg's L, l, R, r [m]."""
        robot = self.robot
        return {
            "joint_offsets_rad": list(robot.joint_offsets_rad),
            "L_m": list(robot.L),
            "l_m": list(robot.l),
            "R_m": list(robot.R),
            "r_m": list(robot.r),
        }


def _solve(ident: Identification, joints: np.ndarray, measured: np.ndarray, start: np.ndarray):
    from scipy.optimize import least_squares  # here: the server imports this module at start

    lower, upper = ident.bounds()
    x0 = np.clip(start, lower, upper)
    return least_squares(
        ident.residuals,
        x0,
        jac=lambda p, q, y: ident.jacobian(p, q).reshape(-1, len(p)),
        bounds=(lower, upper),
        loss="soft_l1",
        f_scale=1e-3,  # residuals beyond ~1 mm count linearly: an outlier cannot drag the fit
        x_scale="jac",
        args=(joints, measured),
    )


def _frame_guess(nominal: PerLegRotaryDelta, joints: np.ndarray, measured: np.ndarray):
    """A starting frame by Kabsch's method on the nominal FK (no prior on where it is)."""
    points = nominal.fk(joints).points
    ok = np.isfinite(points).all(axis=1) & np.isfinite(measured).all(axis=1)
    p, y = points[ok], measured[ok]
    pc, yc = p - p.mean(axis=0), y - y.mean(axis=0)
    u, _, vt = np.linalg.svd(yc.T @ pc)  # P - tm = Rm y  ->  Rm = V diag(1, 1, d) U^T
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    position = p.mean(axis=0) - rotation @ y.mean(axis=0)
    yaw = math.atan2(rotation[1, 0], rotation[0, 0])
    pitch = math.asin(-max(-1.0, min(1.0, rotation[2, 0])))
    roll = math.atan2(rotation[2, 1], rotation[2, 2])
    return MeasurementFrame(tuple(position), (roll, pitch, yaw))


def fit(
    nominal: PerLegRotaryDelta,
    joints: Any,
    measured: Any,
    holdout: int,
    parameters: str = "offsets",
) -> FitResult:
    """Fit ``parameters`` to pairs and validate on the last ``holdout`` of them.

    joints (N, 3) [rad] as the controller reads them; measured (N, 3) [m] in the
    measurement frame; the last ``holdout`` rows are held out (never fitted).

    Raises:
        CalibrationError: for bad shapes, non-finite values, or too few pairs.
    """
    q = np.asarray(joints, dtype=float)
    y = np.asarray(measured, dtype=float)
    if q.ndim != 2 or q.shape[1:] != (3,) or y.shape != q.shape:
        raise CalibrationError(f"pairs: joints {q.shape} and measured {y.shape} must be (N, 3)")
    if not (np.isfinite(q).all() and np.isfinite(y).all()):
        raise CalibrationError("pairs: every joint angle and measurement must be finite")
    ident = identification(nominal, parameters)
    n_fit = len(q) - holdout
    if holdout < 1 or n_fit * 3 < 2 * len(ident.initial):
        raise CalibrationError(
            f"pairs: {len(q)} pairs with {holdout} held out leave too few to fit "
            f"{len(ident.initial)} parameters"
        )
    fq, fy = q[:n_fit], y[:n_fit]
    frame0 = _frame_guess(nominal, fq, fy)
    # the current model: nominal robot, only the frame fitted
    current = Identification(nominal, frame0, FRAME)
    before = _solve(current, fq, fy, current.initial)
    _, frame_before = current.unpack(before.x)
    # the new fit, from the current model's frame
    ident = identification(nominal, parameters, frame_before)
    after = _solve(ident, fq, fy, ident.initial)
    robot, frame = ident.unpack(after.x)
    res_before = current.residuals(before.x, q, y).reshape(-1, 3)
    res_after = ident.residuals(after.x, q, y).reshape(-1, 3)
    return FitResult(
        parameters=parameters,
        robot=robot,
        frame=frame,
        rmse_before_m=rmse(res_before[:n_fit]),
        rmse_after_m=rmse(res_after[:n_fit]),
        holdout_before_m=rmse(res_before[n_fit:]),
        holdout_rmse_m=rmse(res_after[n_fit:]),
        observability=ident.observability(after.x, fq),
        residuals_before=res_before,
        residuals_after=res_after,
        holdout=holdout,
    )

"""Kinematic identification: predicted measurements, their Jacobian, and what data can pin.

A calibration measures the platform from outside (motion capture, a probe) while the
robot reports its joint values q. The model of one measurement is

    y = Rm^T (FK(q; theta) - tm)                                          (1)

with FK the per-leg model (kinematics.per_leg: joint offsets o_i, L_i, l_i, R_i, r_i,
base angles alpha_i) and (tm, Rm) the measurement frame: its origin and axes in the base
frame, Rm = Rz(yaw) Ry(pitch) Rx(roll). A marker fixed on the platform away from its
centre only moves tm (the platform keeps its orientation), so it needs no parameter.

The Jacobian of (1) is analytic. Each leg keeps |P - C_i|^2 = l_i^2; with w_i = P - C_i,
differentiating gives w_i . dP = w_i . dC_i + l_i dl_i (the velocity kinematics of
kinematics.differential, thesis eq. 3.59-3.64, with parameters in place of joints), so

    dP/dp = M^-1 e_i s_i,   M = [w_1; w_2; w_3],   s_i = w_i . dC_i/dp  (or l_i for l_i)

for a parameter p of leg i, and dy/dp = Rm^T dP/dp. Which combinations the data cannot
pin down shows as small singular values of the column-scaled Jacobian (``observability``);
``select_poses`` picks joint sets that make them large (greedy D-optimal design).

Pure NumPy; the fit itself (scipy.optimize.least_squares with a robust loss and the
``bounds`` below) is the caller's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._arrays import as_vectors
from .differential import _inverse_rows
from .errors import InvalidGeometryError, ShapeError
from .per_leg import PerLegRotaryDelta, Triple

GROUPS = ("offsets", "L", "l", "R", "r", "angles", "frame_position", "frame_rotation")
"""Parameter groups, three values each, in the order of the parameter vector."""

_ROBOT_FIELDS = {
    "offsets": "joint_offsets_rad",
    "L": "L",
    "l": "l",
    "R": "R",
    "r": "r",
    "angles": "angles_rad",
}

BOUND_HALF_WIDTHS = {
    "offsets": math.radians(15.0),
    "L": 0.005,
    "l": 0.005,
    "R": 0.005,
    "r": 0.005,
    "angles": math.radians(5.0),
    "frame_position": 1.0,
    "frame_rotation": math.pi,
}
"""Default bounds about the nominal value per group [rad or m]: physically plausible
errors of a built robot (a servo horn a few teeth off, rods cut to a few mm), wide for
the measurement frame, which may be anywhere."""


def rpy_matrix(rpy: Any) -> np.ndarray:
    """Rotation Rz(yaw) Ry(pitch) Rx(roll) of rpy = (roll, pitch, yaw) [rad], shape (3, 3)."""
    matrices = _rpy_factors(rpy)
    return matrices[2] @ matrices[1] @ matrices[0]


def _rpy_factors(rpy: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a, b, c = (float(v) for v in rpy)
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), *_cs(c)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    rz = np.array([[cc, -sc, 0.0], [sc, cc, 0.0], [0.0, 0.0, 1.0]])
    return rx, ry, rz


def _cs(angle: float) -> tuple[float, float]:
    return math.cos(angle), math.sin(angle)


def _rpy_derivatives(rpy: Any) -> list[np.ndarray]:
    """d Rm / d roll, d pitch, d yaw, each (3, 3)."""
    rx, ry, rz = _rpy_factors(rpy)
    gx = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # generators: dR = R G
    gy = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    gz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    return [rz @ ry @ rx @ gx, rz @ ry @ gy @ rx, rz @ gz @ ry @ rx]


@dataclass(frozen=True)
class MeasurementFrame:
    """Where the external measurement's frame sits in the base frame.

    Attributes:
        position_m: its origin in the base frame [m].
        rpy_rad: its axes as (roll, pitch, yaw) [rad]: Rm = Rz(yaw) Ry(pitch) Rx(roll).
    """

    position_m: Triple = (0.0, 0.0, 0.0)
    rpy_rad: Triple = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("position_m", "rpy_rad"):
            values = as_vectors(getattr(self, name), name)
            if values.shape != (3,) or not np.isfinite(values).all():
                raise ShapeError(f"{name}: expected three finite numbers, got {values.tolist()}")
            object.__setattr__(self, name, tuple(float(v) for v in values))

    @property
    def rotation(self) -> np.ndarray:
        """Rm, the frame's axes in the base frame (columns), shape (3, 3)."""
        return rpy_matrix(self.rpy_rad)

    def from_base(self, points: Any) -> np.ndarray:
        """Base-frame points [m] (*, 3) in the measurement frame: Rm^T (P - tm)."""
        return (as_vectors(points, "points") - np.array(self.position_m)) @ self.rotation

    def to_base(self, measured: Any) -> np.ndarray:
        """Measurement-frame points [m] (*, 3) in the base frame: Rm y + tm."""
        return as_vectors(measured, "measured") @ self.rotation.T + np.array(self.position_m)


@dataclass(frozen=True)
class Observability:
    """What a set of poses can tell about the parameters.

    names: the parameters, in vector order. singular_values: of the Jacobian with each
    column scaled to unit norm (descending). condition_number: largest / smallest
    (inf when one is 0). unobservable: names of the parameters that take part in a
    direction the data cannot see (relative singular value below the tolerance).
    combinations: those directions written out ("+0.71 R[0] -0.71 r[0]").
    covariance_per_m2: the parameters' covariance for unit measurement noise [unit^2/m^2]
    over the observable directions (pseudo-inverse of J^T J).
    """

    names: tuple[str, ...]
    singular_values: np.ndarray
    condition_number: float
    unobservable: tuple[str, ...]
    combinations: tuple[str, ...]
    covariance_per_m2: np.ndarray = field(repr=False)

    def standard_deviations(self, noise_m: float) -> dict[str, float]:
        """Each parameter's standard deviation [rad or m] for white measurement noise of
        ``noise_m`` [m] per axis (linearised; unobservable directions left out)."""
        sd = np.sqrt(np.maximum(np.diag(self.covariance_per_m2), 0.0)) * noise_m
        return dict(zip(self.names, sd.tolist(), strict=True))


@dataclass(frozen=True)
class Identification:
    """The parameter vector of a calibration and the measurement model (1) over it.

    Attributes:
        nominal: the model the free parameters start from and the fixed ones keep.
        frame: the measurement frame's starting (or fixed) value.
        groups: the free parameter groups, any of ``GROUPS``; three values each (leg order,
            or x, y, z / roll, pitch, yaw for the frame).

    Raises:
        InvalidGeometryError: for an unknown or repeated group.
    """

    nominal: PerLegRotaryDelta
    frame: MeasurementFrame = MeasurementFrame()
    groups: tuple[str, ...] = ("offsets", "frame_position", "frame_rotation")

    def __post_init__(self) -> None:
        groups = tuple(self.groups)
        for group in groups:
            if group not in GROUPS:
                raise InvalidGeometryError(f"groups: unknown group {group!r} (one of {GROUPS})")
        if len(set(groups)) != len(groups):
            raise InvalidGeometryError(f"groups: {groups} names a group twice")
        object.__setattr__(self, "groups", tuple(g for g in GROUPS if g in groups))

    # ---- the parameter vector ----
    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in vector order, e.g. ("offsets[0]", ..., "frame_rotation[2]")."""
        return tuple(f"{g}[{i}]" for g in self.groups for i in range(3))

    def vector(self, robot: PerLegRotaryDelta, frame: MeasurementFrame) -> np.ndarray:
        """The free parameters' values of a model and frame, shape (3 * len(groups),)."""
        values: list[float] = []
        for group in self.groups:
            if group == "frame_position":
                values.extend(frame.position_m)
            elif group == "frame_rotation":
                values.extend(frame.rpy_rad)
            else:
                values.extend(getattr(robot, _ROBOT_FIELDS[group]))
        return np.array(values, dtype=float)

    @property
    def initial(self) -> np.ndarray:
        """The vector of the nominal model and frame (a fit's starting point)."""
        return self.vector(self.nominal, self.frame)

    def unpack(self, params: Any) -> tuple[PerLegRotaryDelta, MeasurementFrame]:
        """The model and frame of a parameter vector.

        Raises:
            ShapeError: for a vector of the wrong length.
            InvalidGeometryError: for values that are no Delta (naming the leg).
        """
        p = np.asarray(params, dtype=float)
        if p.shape != (3 * len(self.groups),):
            raise ShapeError(f"params: expected shape ({3 * len(self.groups)},), got {p.shape}")
        changes: dict[str, tuple[float, ...]] = {}
        position, rpy = self.frame.position_m, self.frame.rpy_rad
        for k, group in enumerate(self.groups):
            values = tuple(float(v) for v in p[3 * k : 3 * k + 3])
            if group == "frame_position":
                position = values  # type: ignore[assignment]
            elif group == "frame_rotation":
                rpy = values  # type: ignore[assignment]
            else:
                changes[_ROBOT_FIELDS[group]] = values
        robot = self.nominal.with_values(**changes) if changes else self.nominal
        return robot, MeasurementFrame(position, rpy)

    def bounds(self, half_widths: dict[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) bounds about the nominal vector: ``BOUND_HALF_WIDTHS`` unless
        ``half_widths`` overrides some groups; lengths kept above 1 mm and r >= 0."""
        widths = {**BOUND_HALF_WIDTHS, **(half_widths or {})}
        centre = self.initial
        half = np.repeat([widths[g] for g in self.groups], 3)
        lower, upper = centre - half, centre + half
        for k, group in enumerate(self.groups):
            if group in ("L", "l", "R"):
                lower[3 * k : 3 * k + 3] = np.maximum(lower[3 * k : 3 * k + 3], 1e-3)
            elif group == "r":
                lower[3 * k : 3 * k + 3] = np.maximum(lower[3 * k : 3 * k + 3], 0.0)
        return lower, upper

    # ---- the measurement model and its Jacobian ----
    def predict(self, params: Any, joints: Any) -> np.ndarray:
        """Predicted measurements (1) [m], shape (N, 3), for joint values (N, 3) [rad];
        NaN rows where the model has no FK for those joints."""
        robot, frame = self.unpack(params)
        q = _joints(joints)
        return frame.from_base(robot.fk(q).points)

    def residuals(self, params: Any, joints: Any, measured: Any) -> np.ndarray:
        """predict - measured, flattened to (3 N,) [m] (the function least_squares fits).

        A pose without FK for these parameters gets residuals of 1 m: far off, yet finite,
        so a solver's trial step there is rejected instead of failing.
        """
        y = as_vectors(measured, "measured")
        diff = self.predict(params, joints) - y
        return np.where(np.isfinite(diff), diff, 1.0).ravel()

    def jacobian(self, params: Any, joints: Any) -> np.ndarray:
        """d predict / d params, shape (N, 3, P) [m per rad or m per m], analytic (module
        docstring). NaN rows where FK fails; inf/NaN at a parallel singularity."""
        robot, frame = self.unpack(params)
        q = _joints(joints)
        points = robot.fk(q).points
        knees = robot.knees(q)
        w = points[:, None, :] - knees  # (N, legs, 3)
        with np.errstate(all="ignore"):
            m_inv = _inverse_rows(w)  # (N, 3, legs)
        theta = q + np.array(robot.joint_offsets_rad)
        alpha = np.array(robot.angles_rad)
        c, s = np.cos(alpha), np.sin(alpha)
        L = np.array(robot.L)
        reach = np.array(robot.Rbar) + L * np.cos(theta)
        zeros = np.zeros_like(theta)

        def along(dx: Any, dy: Any, dz: Any) -> np.ndarray:
            """w_i . dC_i for the legs' derivative vectors, shape (N, legs)."""
            return w[..., 0] * dx + w[..., 1] * dy + w[..., 2] * dz

        radial = along(c + zeros, s + zeros, zeros)
        leg_speeds = {
            "offsets": along(-c * L * np.sin(theta), -s * L * np.sin(theta), -L * np.cos(theta)),
            "L": along(c * np.cos(theta), s * np.cos(theta), -np.sin(theta)),
            "l": np.broadcast_to(np.array(robot.l), theta.shape),
            "R": radial,
            "r": -radial,
            "angles": along(-s * reach, c * reach, zeros),
        }
        rm = frame.rotation
        columns: list[np.ndarray] = []
        for group in self.groups:
            if group == "frame_position":
                columns.extend(np.broadcast_to(-rm[j, :], points.shape) for j in range(3))
            elif group == "frame_rotation":
                relative = points - np.array(frame.position_m)
                columns.extend(relative @ d for d in _rpy_derivatives(frame.rpy_rad))
            else:
                speeds = leg_speeds[group]
                with np.errstate(all="ignore"):
                    columns.extend((m_inv[:, :, i] * speeds[:, i, None]) @ rm for i in range(3))
        return np.stack(columns, axis=-1)

    def observability(self, params: Any, joints: Any, tolerance: float = 1e-6) -> Observability:
        """Singular values, condition number and unobservable parameters at ``params`` for
        the poses ``joints`` (N, 3) [rad].

        Columns are scaled to unit norm first, so radians and metres compare. A direction
        with singular value below ``tolerance`` times the largest is unobservable: its
        parameters (components over 0.1 of the direction's largest) are listed.

        Raises:
            ShapeError: for malformed joints; InvalidGeometryError for a bad ``params``.
        """
        jac = self.jacobian(params, joints)
        return observability_of(jac.reshape(-1, jac.shape[-1]), self.names, tolerance)


def observability_of(rows: Any, names: Sequence[str], tolerance: float = 1e-6) -> Observability:
    """``Observability`` of a stacked Jacobian ``rows`` (M, P) of parameters ``names`` (P).

    Rows with a non-finite entry are dropped; columns are scaled to unit norm, so radians
    and metres compare; a direction whose singular value is below ``tolerance`` times the
    largest is unobservable, and its parameters (components over 0.1 of the direction's
    largest) are listed. Any measurement model may use it (the 3D one above, the z-only
    touches of a probe).

    Raises:
        ShapeError: when ``rows`` is not (M, len(names)).
    """
    rows = np.asarray(rows, dtype=float)
    names = tuple(names)
    if rows.ndim != 2 or rows.shape[1] != len(names):
        raise ShapeError(f"rows: expected shape (M, {len(names)}), got {rows.shape}")
    rows = rows[np.isfinite(rows).all(axis=1)]
    norms = np.linalg.norm(rows, axis=0)
    scale = np.where(norms > 0.0, norms, 1.0)
    scaled = rows / scale
    _, sigma, vt = np.linalg.svd(scaled, full_matrices=True)
    n_params = scaled.shape[1]
    sigma_full = np.zeros(n_params)
    sigma_full[: len(sigma)] = sigma
    top = sigma_full[0] if n_params else 0.0
    weak = sigma_full <= tolerance * top
    involved: set[int] = set()
    combos = []
    for k in np.flatnonzero(weak):
        v = vt[k]
        big = np.flatnonzero(np.abs(v) >= 0.1 * np.abs(v).max())
        involved.update(big.tolist())
        combos.append(" ".join(f"{v[j]:+.2f} {names[j]}" for j in big))
    kept = ~weak
    inv_sigma2 = np.zeros(n_params)
    inv_sigma2[kept] = 1.0 / sigma_full[kept] ** 2
    cov_scaled = (vt.T * inv_sigma2) @ vt
    covariance = cov_scaled / np.outer(scale, scale)
    with np.errstate(divide="ignore"):
        condition = float(top / sigma_full[-1]) if n_params else 1.0
    return Observability(
        names=names,
        singular_values=sigma_full,
        condition_number=condition,
        unobservable=tuple(names[j] for j in sorted(involved)),
        combinations=tuple(combos),
        covariance_per_m2=covariance,
    )


def _joints(joints: Any) -> np.ndarray:
    q = as_vectors(joints, "joints")
    if q.ndim != 2:
        raise ShapeError(f"joints: expected shape (N, 3), got {q.shape}")
    return q


def candidate_poses(
    robot: PerLegRotaryDelta,
    count: int = 2000,
    joint_range_rad: Sequence[float] = (-0.5, 1.5),
    min_dexterity: float = 0.2,
    seed: int = 0,
) -> np.ndarray:
    """Joint sets (M <= count, 3) [rad] drawn uniformly in ``joint_range_rad`` that the
    robot can take safely: FK exists, the platform hangs below every knee, and the
    dexterity (inverse condition number of dP/dq) is at least ``min_dexterity``."""
    low, high = (float(v) for v in joint_range_rad)
    if not low < high:
        raise ShapeError(f"joint_range_rad: expected (low, high) with low < high, got {low, high}")
    q = np.random.default_rng(seed).uniform(low, high, (count, 3))
    points, ok = robot.fk(q)
    below = points[:, 2] < robot.knees(q)[..., 2].min(axis=-1)
    good = ok & below & (np.nan_to_num(robot.dexterity(q)) >= min_dexterity)
    return q[good]


def select_poses(
    identification: Identification,
    count: int,
    candidates: Any = None,
    params: Any = None,
    seed: int = 0,
) -> np.ndarray:
    """``count`` poses (count, 3) [rad] that make the free parameters observable.

    Greedy D-optimal design: from the candidates (default ``candidate_poses`` of the
    nominal robot), add one at a time the pose that most increases log det(J^T J + eps I)
    of the column-scaled Jacobian (matrix determinant lemma: one 3x3 determinant per
    candidate and step). Spreads poses over the workspace where the parameters' effects
    differ most; directions no pose can see (``observability().unobservable``) stay so.

    Raises:
        ShapeError: when fewer candidates than ``count`` are usable.
    """
    params = identification.initial if params is None else params
    if candidates is None:
        robot, _ = identification.unpack(params)
        candidates = candidate_poses(robot, seed=seed)
    q = _joints(candidates)
    jac = identification.jacobian(params, q)
    usable = np.isfinite(jac).all(axis=(1, 2))
    q, jac = q[usable], jac[usable]
    if len(q) < count:
        raise ShapeError(f"count: {count} poses asked, only {len(q)} usable candidates")
    norms = np.sqrt(np.mean(np.sum(jac * jac, axis=1), axis=0))
    jac = jac / np.where(norms > 0.0, norms, 1.0)
    n = jac.shape[-1]
    info = 1e-6 * np.eye(n)
    chosen: list[int] = []
    available = np.ones(len(q), dtype=bool)
    for _ in range(count):
        inv = np.linalg.inv(info)
        gain = np.eye(3) + np.einsum("kip,pq,kjq->kij", jac, inv, jac)
        score = np.where(available, np.linalg.slogdet(gain)[1], -np.inf)
        best = int(np.argmax(score))
        chosen.append(best)
        available[best] = False
        info = info + jac[best].T @ jac[best]
    return q[chosen]

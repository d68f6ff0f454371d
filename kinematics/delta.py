"""What both Delta types share: IK/FK dispatch (single point or batch), legs and frames.

A Delta leg is a sphere of radius ``l`` (the parallelogram) around a knee point that
one actuator moves along a curve: a circle for a rotary Delta, a line for a linear one.
Subclasses supply the per-leg formulas (written once for NumPy columns and floats,
see ``_xp``); this module turns them into broadcasting, chunked batch calls and a
scalar fast path.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from . import differential, workspace
from ._arrays import as_vectors, is_scalar_triple, triple_floats
from ._xp import ARRAYS, FLOATS, LEG_COS, LEG_SIN
from .errors import ShapeError
from .results import FKResult, IKResult, LegPoints, Projection
from .spheres import intersect_below, intersect_below_point

# Points per chunk: temporaries of this size stay in the L2 cache, which makes the
# batch paths 2-3x faster than whole-array temporaries at N = 1e6.
CHUNK = 8192

_NAN3 = (math.nan, math.nan, math.nan)


class DeltaKinematics(ABC):
    """Mixin for a 3-leg Delta whose platform keeps its orientation.

    Subclasses are frozen dataclasses with the per-leg hooks below (``SymmetricDelta``
    for three equal legs, ``PerLegRotaryDelta`` for legs that each have their own).
    """

    # ---- the legs' fixed points ----
    @abstractmethod
    def _rod_lengths(self) -> float | tuple[float, float, float]:
        """Parallelogram length [m]: one for all legs, or one per leg."""

    @abstractmethod
    def _anchors(self) -> tuple[np.ndarray, np.ndarray]:
        """(hips, ankle offsets), each (3 legs, 3) [m]: the actuated joints in the base
        frame and the platform joints relative to the platform centre."""

    # ---- per-leg formulas, on NumPy columns or floats (``xp`` is _xp.ARRAYS / FLOATS) ----
    @abstractmethod
    def _leg_joint(self, leg: int, x: Any, y: Any, z: Any, near: Any, xp: Any) -> Any:
        """Joint value of one leg for platform centre (x, y, z); NaN if out of reach."""

    @abstractmethod
    def _leg_discriminant(self, leg: int, x: Any, y: Any, z: Any) -> Any:
        """The IK's discriminant of one leg: >= 0 exactly where the leg reaches."""

    @abstractmethod
    def _leg_centre(self, leg: int, q: Any, xp: Any) -> tuple[Any, Any, Any]:
        """Shifted knee point of one leg at joint value q: the centre of its sphere."""

    @abstractmethod
    def _leg_centre_derivatives(self, leg: int, q: np.ndarray) -> tuple[tuple, tuple]:
        """First and second derivatives of the shifted knee w.r.t. the joint value."""

    @abstractmethod
    def _leg_signed_distance(self, leg: int, x: Any, y: Any, z: Any) -> Any:
        """Distance [m] to one leg's workspace boundary, negative inside."""

    def _fk_branch_ok(self, q: Any, x: Any, y: Any, z: Any) -> Any:
        """Whether an FK solution is on the robot's physical branch (all are, by default)."""
        return True

    # ---- inverse kinematics ----
    def ik(self, points: Any, near: Any = None) -> IKResult:
        """Joint values that put the platform centre at ``points``.

        Args:
            points: platform centres in the base frame [m], shape (*, 3).
            near: current joints, shape (*, 3) broadcastable with ``points``. When given,
                each leg takes the root with the smallest absolute travel from it;
                otherwise the normal working mode (knee out for a rotary Delta).

        Returns:
            IKResult(joints (*, 3), ok (*)). Unreachable or non-finite points give
            ok=False and NaN joints; nothing raises for them.

        Raises:
            ShapeError: when an argument is not numeric or not shaped (*, 3).
        """
        if is_scalar_triple(points) and (near is None or is_scalar_triple(near)):
            single = self._ik_point(points, near)
            if single is not None:
                return single
        pts = as_vectors(points, "points")
        nearest = None if near is None else as_vectors(near, "near")
        if nearest is not None:
            pts, nearest = _broadcast_pair(pts, nearest, "points", "near")
        flat = pts.reshape(-1, 3)
        near_flat = None if nearest is None else nearest.reshape(-1, 3)
        joints = np.empty_like(flat)
        with np.errstate(all="ignore"):
            for a in range(0, len(flat), CHUNK):
                x, y, z = flat[a : a + CHUNK].T
                for leg in range(3):
                    ref = None if near_flat is None else near_flat[a : a + CHUNK, leg]
                    joints[a : a + CHUNK, leg] = self._leg_joint(leg, x, y, z, ref, ARRAYS)
        return _masked(joints, flat, pts.shape[:-1], IKResult)

    def _ik_point(self, points: Any, near: Any) -> IKResult | None:
        x, y, z = triple_floats(points, "points")
        refs = _NAN3 if near is None else triple_floats(near, "near")
        try:
            joints = [
                self._leg_joint(leg, x, y, z, None if near is None else refs[leg], FLOATS)
                for leg in range(3)
            ]
        except (ZeroDivisionError, OverflowError, ValueError):
            return None  # degenerate corner or inf: let the NumPy path answer it
        return _single(joints, (x, y, z, *refs[: 3 if near is not None else 0]), IKResult)

    # ---- forward kinematics ----
    def fk(self, joints: Any) -> FKResult:
        """Platform centre for joint values (closed-form three-sphere intersection).

        Args:
            joints: joint values [rad rotary, m linear], shape (*, 3).

        Returns:
            FKResult(points (*, 3) [m] in the base frame, ok (*)). The solution below the
            knees is returned; ok=False and NaN where the spheres do not meet.
        """
        if is_scalar_triple(joints):
            single = self._fk_point(joints)
            if single is not None:
                return single
        array = as_vectors(joints, "joints")
        flat_q = array.reshape(-1, 3)
        points = np.empty_like(flat_q)
        with np.errstate(all="ignore"):
            for a in range(0, len(flat_q), CHUNK):
                chunk = flat_q[a : a + CHUNK]
                c1, c2, c3 = [self._leg_centre(leg, chunk[:, leg], ARRAYS) for leg in range(3)]
                columns = intersect_below(c1, c2, c3, self._rod_lengths())
                valid = self._fk_branch_ok(chunk.T, *columns)
                for axis, column in enumerate(columns):
                    points[a : a + CHUNK, axis] = np.where(valid, column, np.nan)
        return _masked(points, flat_q, array.shape[:-1], FKResult)

    def _fk_point(self, joints: Any) -> FKResult | None:
        q = triple_floats(joints, "joints")
        try:
            c1, c2, c3 = [self._leg_centre(leg, q[leg], FLOATS) for leg in range(3)]
        except (OverflowError, ValueError):
            return None  # inf joints: let the NumPy path answer it
        point = intersect_below_point(c1, c2, c3, self._rod_lengths())
        if not self._fk_branch_ok(q, *point):
            point = _NAN3
        return _single(point, (*q, *point), FKResult)

    # ---- legs ----
    def knees(self, joints: Any) -> np.ndarray:
        """Radially shifted knee points C_i (thesis eq. 3.28), shape (*, 3 legs, 3) [m].

        Each is the centre of a sphere of radius ``l`` on which the platform centre lies.
        """
        q = as_vectors(joints, "joints")
        with np.errstate(all="ignore"):
            legs = [np.stack(self._leg_centre(i, q[..., i], ARRAYS), -1) for i in range(3)]
        return np.stack(legs, axis=-2)

    def leg_points(self, joints: Any) -> LegPoints:
        """Physical joint centres (hips, knees, ankles) of the three legs, for drawing."""
        points = self.fk(joints).points
        hip_points, radial = self._anchors()
        hips = np.broadcast_to(hip_points, self.knees(joints).shape)
        knees = self.knees(joints) + radial
        ankles = points[..., None, :] + radial
        return LegPoints(hips, knees, ankles)

    # ---- velocity, acceleration, singularity (see differential.py) ----
    jacobian = differential.jacobian
    joint_velocity = differential.joint_velocity
    point_velocity = differential.point_velocity
    joint_acceleration = differential.joint_acceleration
    dexterity = differential.dexterity

    # ---- workspace (see workspace.py) ----
    h = workspace.h
    reachable = workspace.reachable
    signed_distance = workspace.signed_distance

    def project(self, point: Any, margin: float = 0.0, z_max: float | None = None) -> Projection:
        """Nearest reachable point to ``point`` (see :func:`workspace.project`)."""
        return workspace.project(self, point, margin=margin, z_max=z_max)


class SymmetricDelta(DeltaKinematics):
    """Three equal legs at 0, 120, 240 deg: ``l`` (parallelogram length [m]), ``R`` (base
    radius [m]) and ``r`` (platform radius [m]) shared by all."""

    l: float
    R: float
    r: float

    @property
    def Rbar(self) -> float:
        """Radial shift R - r [m] that puts all three legs' ends at the platform centre."""
        return self.R - self.r

    def _rod_lengths(self) -> float:
        return self.l

    def _anchors(self) -> tuple[np.ndarray, np.ndarray]:
        return self.R * _UNIT_RADIAL, self.r * _UNIT_RADIAL


_UNIT_RADIAL = np.array([[c, s, 0.0] for c, s in zip(LEG_COS, LEG_SIN, strict=True)])


def _broadcast_pair(
    a: np.ndarray, b: np.ndarray, name_a: str, name_b: str
) -> tuple[np.ndarray, np.ndarray]:
    try:
        shape = np.broadcast_shapes(a.shape, b.shape)
    except ValueError as exc:
        raise ShapeError(
            f"{name_b}: shape {b.shape} does not broadcast with {name_a} shape {a.shape}"
        ) from exc
    return np.broadcast_to(a, shape), np.broadcast_to(b, shape)


def _masked(values: np.ndarray, inputs: np.ndarray, shape: tuple, kind: type) -> Any:
    """NaN every row with a non-finite value or input; reshape to the batch shape."""
    ok = np.isfinite(values).all(axis=-1) & np.isfinite(inputs).all(axis=-1)
    values[~ok] = np.nan
    return kind(values.reshape(*shape, 3), ok.reshape(shape))


def _single(values: Any, checked: tuple, kind: type) -> Any:
    ok = all(math.isfinite(v) for v in values) and all(math.isfinite(v) for v in checked)
    array = np.array(values, dtype=np.float64) if ok else np.full(3, np.nan)
    return kind(array, np.bool_(ok))

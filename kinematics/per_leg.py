"""A rotary Delta whose legs each have their own geometry: what a real robot is.

Hand-cut rods, a servo horn a tooth off, a motor mount a little out of place: the thesis
blames its 4-8 mm FK errors against VICON on exactly these (ch. 6.1, Table 6.2). Here
leg i has its own upper link L_i, rod l_i, base radius R_i, platform radius r_i, the angle
alpha_i of its base position (nominally 0, 120, 240 deg) and a joint offset o_i, the angle
the mechanism is turned by against the joint value q_i the servo reports:

    theta_i = q_i + o_i
    C_i = Rz(alpha_i) [Rbar_i + L_i cos(theta_i), 0, -L_i sin(theta_i)]     (eq. 3.28)

with Rbar_i = R_i - r_i (the platform joint of leg i lies at r_i along alpha_i, so the
radial shift of eq. 3.20 still puts every leg's end at the platform centre). FK is the
intersection of three spheres of radii l_i about C_i (kinematics.spheres, unequal radii);
the IK of each leg is the symmetric one (eq. 3.40-3.46) with that leg's numbers, minus
o_i. With equal legs and zero offsets it is ``RotaryDelta`` (tested to 1e-12).

Only R_i - r_i enters the kinematics: R_i and r_i cannot be told apart by any
measurement (kinematics.identification reports such parameters).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ._xp import LEG_ANGLES_RAD, LEG_COS, LEG_SIN
from .delta import DeltaKinematics
from .errors import InvalidGeometryError
from .rotary import RotaryDelta

Triple = tuple[float, float, float]


def _triple(name: str, value: Any) -> Triple:
    try:
        values = tuple(float(v) for v in value)
    except (TypeError, ValueError) as exc:
        raise InvalidGeometryError(f"{name} = {value!r}: expected three numbers") from exc
    if len(values) != 3:
        raise InvalidGeometryError(f"{name} = {value!r}: expected three numbers, one per leg")
    for i, v in enumerate(values):
        if not math.isfinite(v):
            raise InvalidGeometryError(f"{name}[{i}] = {v!r}: must be finite")
    return values[0], values[1], values[2]


def _mean(values: Triple) -> float:
    """Mean of three values, exact when they are equal."""
    return values[0] if values[0] == values[1] == values[2] else math.fsum(values) / 3.0


def _direction(leg: int, angle: float) -> tuple[float, float]:
    """cos, sin of a leg's angle; the nominal angles give the exact table values."""
    if angle == LEG_ANGLES_RAD[leg]:
        return LEG_COS[leg], LEG_SIN[leg]
    return math.cos(angle), math.sin(angle)


@dataclass(frozen=True)
class PerLegRotaryDelta(DeltaKinematics):
    """Rotary Delta with per-leg geometry and joint offsets (module docstring's model).

    Attributes (each three values, leg order):
        L: upper link lengths, motor axis to knee [m].
        l: lower link (rod) lengths, knee to platform joint [m]; l_i > L_i.
        R: base radii, centre to motor axis [m].
        r: platform radii, centre to platform joint [m]; 0 <= r_i <= R_i.
        joint_offsets_rad: o_i, added to the reported joint value to give the mechanism's
            angle theta_i = q_i + o_i [rad].
        angles_rad: alpha_i, the direction of leg i's base position about z [rad]
            (nominal 0, 2 pi / 3, 4 pi / 3).

    Raises:
        InvalidGeometryError: naming the field and leg (``l[2] = ...``) for a value that
            cannot be a Delta leg.
    """

    L: Triple
    l: Triple
    R: Triple
    r: Triple
    joint_offsets_rad: Triple = (0.0, 0.0, 0.0)
    angles_rad: Triple = LEG_ANGLES_RAD
    _dirs: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("L", "l", "R", "r", "joint_offsets_rad", "angles_rad"):
            object.__setattr__(self, name, _triple(name, getattr(self, name)))
        for i in range(3):
            for name in ("L", "l", "R"):
                if not getattr(self, name)[i] > 0.0:
                    raise InvalidGeometryError(
                        f"{name}[{i}] = {getattr(self, name)[i]} m: must be > 0"
                    )
            if not self.l[i] > self.L[i]:
                raise InvalidGeometryError(
                    f"l[{i}] = {self.l[i]} m: the lower link must be longer than "
                    f"L[{i}] = {self.L[i]} m (eq. 3.1)"
                )
            if not 0.0 <= self.r[i] <= self.R[i]:
                raise InvalidGeometryError(
                    f"r[{i}] = {self.r[i]} m: must be in [0, R[{i}] = {self.R[i]} m]"
                )
        dirs = tuple(_direction(i, a) for i, a in enumerate(self.angles_rad))
        object.__setattr__(self, "_dirs", dirs)

    # ---- construction ----
    @classmethod
    def from_symmetric(
        cls,
        robot: RotaryDelta,
        joint_offsets_rad: Any = (0.0, 0.0, 0.0),
        **per_leg: Any,
    ) -> PerLegRotaryDelta:
        """The symmetric ``robot`` as a per-leg model, with ``joint_offsets_rad`` and any of
        ``L``, ``l``, ``R``, ``r``, ``angles_rad`` (three values each) replacing its own."""
        values = {name: (getattr(robot, name),) * 3 for name in ("L", "l", "R", "r")}
        values.update(per_leg)
        return cls(joint_offsets_rad=joint_offsets_rad, **values)

    def with_values(self, **changes: Any) -> PerLegRotaryDelta:
        """A copy with some fields replaced (three values each)."""
        return replace(self, **changes)

    @property
    def Rbar(self) -> Triple:
        """Radial shifts R_i - r_i [m] (eq. 3.20), per leg."""
        return (self.R[0] - self.r[0], self.R[1] - self.r[1], self.R[2] - self.r[2])

    def nominal(self) -> RotaryDelta:
        """The symmetric robot of the legs' mean L, l, R, r (what a controller might assume)."""
        return RotaryDelta(*(_mean(getattr(self, n)) for n in ("L", "l", "R", "r")))

    # ---- hooks of DeltaKinematics ----
    def _rod_lengths(self) -> Triple:
        return self.l

    def _anchors(self) -> tuple[np.ndarray, np.ndarray]:
        unit = np.array([[c, s, 0.0] for c, s in self._dirs])
        return np.array(self.R)[:, None] * unit, np.array(self.r)[:, None] * unit

    def _efg(self, leg: int, x: Any, y: Any, z: Any) -> tuple[Any, Any, Any]:
        """E_i, F_i, G_i of thesis eq. 3.41-3.43 with leg i's own numbers."""
        c, s = self._dirs[leg]
        Rbar, L, l = self.R[leg] - self.r[leg], self.L[leg], self.l[leg]
        xi = c * x + s * y
        E = 2.0 * L * (Rbar - xi)
        F = 2.0 * L * z
        G = x * x + y * y + z * z + (Rbar * Rbar + L * L - l * l) - 2.0 * Rbar * xi
        return E, F, G

    def _leg_discriminant(self, leg: int, x: Any, y: Any, z: Any) -> Any:
        E, F, G = self._efg(leg, x, y, z)
        return E * E + F * F - G * G

    def _leg_joint(self, leg: int, x: Any, y: Any, z: Any, near: Any, xp: Any) -> Any:
        # as RotaryDelta._leg_joint (eq. 3.46, cancellation-free), then theta - o_i
        E, F, G = self._efg(leg, x, y, z)
        offset = self.joint_offsets_rad[leg]
        q = -(F + xp.copysign(xp.sqrt(E * E + F * F - G * G), F))
        knee_out = xp.half_angle(G + E, q) - offset
        if near is None:
            return knee_out
        knee_in = xp.half_angle(q, G - E) - offset
        return xp.where(abs(knee_in - near) < abs(knee_out - near), knee_in, knee_out)

    def _leg_centre(self, leg: int, q: Any, xp: Any) -> tuple[Any, Any, Any]:
        c, s = self._dirs[leg]
        theta = q + self.joint_offsets_rad[leg]
        reach = (self.R[leg] - self.r[leg]) + self.L[leg] * xp.cos(theta)
        return c * reach, s * reach, -self.L[leg] * xp.sin(theta)

    def _leg_centre_derivatives(self, leg: int, q: np.ndarray) -> tuple[tuple, tuple]:
        c, s = self._dirs[leg]
        theta = q + self.joint_offsets_rad[leg]
        sin, cos = self.L[leg] * np.sin(theta), self.L[leg] * np.cos(theta)
        return (-c * sin, -s * sin, -cos), (-c * cos, -s * cos, sin)

    def _leg_signed_distance(self, leg: int, x: Any, y: Any, z: Any) -> Any:
        c, s = self._dirs[leg]
        L, l = self.L[leg], self.l[leg]
        radial = c * x + s * y - (self.R[leg] - self.r[leg])
        along_axis = -s * x + c * y
        rho = np.hypot(radial, z)
        nearest = np.hypot(rho - L, along_axis)
        farthest = np.hypot(rho + L, along_axis)
        return np.maximum(nearest - l, l - farthest)

"""The linear (translatory-actuated) Delta of the 2012 paper (003, eq. 8-14).

Carriage i slides along a fixed rail through B_i = R u_i with unit direction
a_i = [cos(alpha_i) cos(incline), sin(alpha_i) cos(incline), sin(incline)] (eq. 8);
the joint value q_i [m] is the carriage's displacement along it. Vertical towers
(incline = 90 deg) are the common 3D-printer case. With kw_i = P - Rbar u_i (eq. 11,
its second row corrected to use y_P), squaring eq. 10 gives (eq. 14, signs corrected)

    q_i = a_i . kw_i + sqrt((a_i . kw_i)^2 - |kw_i|^2 + l^2)

taking the carriage on the far side of the platform along a_i.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._xp import LEG_COS, LEG_SIN
from .delta import SymmetricDelta
from .errors import InvalidGeometryError
from .rotary import _check_length


@dataclass(frozen=True)
class LinearDelta(SymmetricDelta):
    """Delta robot with carriages on straight rails.

    Attributes:
        l: parallelogram length, carriage joint to platform joint [m].
        R: base radius, centre to the rail reference point B_i [m].
        r: platform radius [m]; r < R.
        incline: rail angle above the base plane [rad], 0 (horizontal) .. pi/2 (vertical).
    """

    l: float
    R: float
    r: float
    incline: float = math.pi / 2
    _rails: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _check_length("l", self.l)
        _check_length("R", self.R)
        _check_length("r", self.r, strict=False)
        if not self.r < self.R:
            raise InvalidGeometryError(f"r = {self.r} m: must be less than R = {self.R} m")
        if not (math.isfinite(self.incline) and 0.0 <= self.incline <= math.pi / 2):
            raise InvalidGeometryError(f"incline = {self.incline!r} rad: must be in [0, pi/2]")
        c, s = math.cos(self.incline), math.sin(self.incline)
        rails = tuple((LEG_COS[i] * c, LEG_SIN[i] * c, s) for i in range(3))
        object.__setattr__(self, "_rails", rails)  # unit rail directions a_i (eq. 8)

    def _rail(self, leg: int) -> tuple[float, float, float]:
        return self._rails[leg]

    def _along_and_norm(self, leg: int, x: Any, y: Any, z: Any) -> tuple[Any, Any]:
        Rbar = self.R - self.r
        kx, ky = x - Rbar * LEG_COS[leg], y - Rbar * LEG_SIN[leg]
        ax, ay, az = self._rail(leg)
        return ax * kx + ay * ky + az * z, kx * kx + ky * ky + z * z

    def _leg_discriminant(self, leg: int, x: Any, y: Any, z: Any) -> Any:
        along, k2 = self._along_and_norm(leg, x, y, z)
        return along * along - k2 + self.l * self.l

    def _leg_joint(self, leg: int, x: Any, y: Any, z: Any, near: Any, xp: Any) -> Any:
        # One physical root (the carriage beyond the platform), so ``near`` has no choice.
        along, k2 = self._along_and_norm(leg, x, y, z)
        return along + xp.sqrt(along * along - k2 + self.l * self.l)

    def _fk_branch_ok(self, q: Any, x: Any, y: Any, z: Any) -> Any:
        """The lower sphere intersection can put a carriage on the platform's side of it
        (the other root of eq. 14): no physical pose has those joints, so FK says not ok."""
        tolerance = -1e-12
        beyond = [q[i] - self._along_and_norm(i, x, y, z)[0] >= tolerance for i in range(3)]
        return beyond[0] & beyond[1] & beyond[2]

    def _leg_centre(self, leg: int, q: Any, xp: Any) -> tuple[Any, Any, Any]:
        Rbar = self.R - self.r
        ax, ay, az = self._rail(leg)
        return Rbar * LEG_COS[leg] + q * ax, Rbar * LEG_SIN[leg] + q * ay, q * az

    def _leg_centre_derivatives(self, leg: int, q: np.ndarray) -> tuple[tuple, tuple]:
        ones, zeros = np.ones_like(q), np.zeros_like(q)
        rail = self._rail(leg)
        return tuple(a * ones for a in rail), (zeros, zeros, zeros)

    def _leg_signed_distance(self, leg: int, x: Any, y: Any, z: Any) -> Any:
        along, k2 = self._along_and_norm(leg, x, y, z)
        return np.sqrt(np.maximum(k2 - along * along, 0.0)) - self.l

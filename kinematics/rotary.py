"""The rotary Delta of the thesis (ch. 3.1): three motors turn upper links of length L.

Leg i lies in the vertical plane at alpha_i = 0, 120, 240 deg. With Rbar = R - r and
theta_i = 0 the upper link horizontal (positive pointing down), the shifted knee is

    C_i = Rz(alpha_i) [Rbar + L cos(theta_i), 0, -L sin(theta_i)]          (eq. 3.28)

and the IK of each leg is E cos(theta) + F sin(theta) + G = 0 (eq. 3.40-3.43), solved
with the half-angle substitution in its cancellation-free form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._xp import LEG_COS, LEG_SIN
from .delta import SymmetricDelta
from .errors import InvalidGeometryError


def _check_length(name: str, value: float, minimum: float = 0.0, strict: bool = True) -> None:
    ok = math.isfinite(value) and (value > minimum if strict else value >= minimum)
    if not ok:
        bound = f"> {minimum}" if strict else f">= {minimum}"
        raise InvalidGeometryError(f"{name} = {value!r} m: must be finite and {bound}")


@dataclass(frozen=True)
class RotaryDelta(SymmetricDelta):
    """Rotary-actuated Delta robot (thesis eq. 3.1-3.88).

    Attributes:
        L: upper link length, motor axis to knee [m].
        l: lower link (parallelogram) length, knee to platform joint [m]; l > L.
        R: base radius, centre to motor axis [m].
        r: platform radius, centre to platform joint [m]; r <= R.
    """

    L: float
    l: float
    R: float
    r: float

    def __post_init__(self) -> None:
        for name in ("L", "l", "R"):
            _check_length(name, getattr(self, name))
        _check_length("r", self.r, strict=False)
        if not self.l > self.L:
            raise InvalidGeometryError(
                f"l = {self.l} m: the lower link must be longer than L = {self.L} m (eq. 3.1)"
            )
        if self.r > self.R:
            raise InvalidGeometryError(f"r = {self.r} m: must not exceed R = {self.R} m")

    def _efg(self, leg: int, x: Any, y: Any, z: Any) -> tuple[Any, Any, Any]:
        """E_i, F_i, G_i of thesis eq. 3.41-3.43."""
        Rbar, L = self.R - self.r, self.L
        xi = x if leg == 0 else LEG_COS[leg] * x + LEG_SIN[leg] * y
        E = 2.0 * L * (Rbar - xi)
        F = 2.0 * L * z
        G = x * x + y * y + z * z + (Rbar * Rbar + L * L - self.l * self.l) - 2.0 * Rbar * xi
        return E, F, G

    def _leg_discriminant(self, leg: int, x: Any, y: Any, z: Any) -> Any:
        E, F, G = self._efg(leg, x, y, z)
        return E * E + F * F - G * G

    def _leg_joint(self, leg: int, x: Any, y: Any, z: Any, near: Any, xp: Any) -> Any:
        E, F, G = self._efg(leg, x, y, z)
        # (G - E) t^2 + 2 F t + (G + E) = 0 (eq. 3.46). With q = -(F + sign(F) sqrt(D)),
        # t = (G + E) / q is the knee-out root and t = q / (G - E) the knee-in one,
        # neither subtracting nearly equal numbers, and G = E needs no special case.
        q = -(F + xp.copysign(xp.sqrt(E * E + F * F - G * G), F))
        knee_out = xp.half_angle(G + E, q)
        if near is None:
            return knee_out
        knee_in = xp.half_angle(q, G - E)
        return xp.where(abs(knee_in - near) < abs(knee_out - near), knee_in, knee_out)

    def _leg_centre(self, leg: int, q: Any, xp: Any) -> tuple[Any, Any, Any]:
        reach = (self.R - self.r) + self.L * xp.cos(q)
        return LEG_COS[leg] * reach, LEG_SIN[leg] * reach, -self.L * xp.sin(q)

    def _leg_centre_derivatives(self, leg: int, q: np.ndarray) -> tuple[tuple, tuple]:
        s, c = self.L * np.sin(q), self.L * np.cos(q)
        first = (-LEG_COS[leg] * s, -LEG_SIN[leg] * s, -c)
        second = (-LEG_COS[leg] * c, -LEG_SIN[leg] * c, s)
        return first, second

    def _leg_signed_distance(self, leg: int, x: Any, y: Any, z: Any) -> Any:
        # In the leg's plane: rho = distance from the motor axis, c = along the axis.
        xi = LEG_COS[leg] * x + LEG_SIN[leg] * y - (self.R - self.r)
        along_axis = -LEG_SIN[leg] * x + LEG_COS[leg] * y
        rho = np.hypot(xi, z)
        nearest = np.hypot(rho - self.L, along_axis)  # to the knee circle's nearest point
        farthest = np.hypot(rho + self.L, along_axis)
        return np.maximum(nearest - self.l, self.l - farthest)


THESIS_DELTA = RotaryDelta(L=0.1558, l=0.2430, R=0.0844, r=0.038)
"""The thesis's robot (eq. 4.11): Rbar = 0.0464 m."""

"""One move, dwell or pause of a program, in the base frame [m, s], and its geometry.

Every move is one curve of the family p(s) = base + u s + r(s) E(phi(s)), s the arc
length [m] from the segment's start:

- a line: base = start, u = the unit direction, r = 0;
- an arc or helix in plane (e1, e2, n) (G17: x, y, z; G18: z, x, y; G19: y, z, x, so
  n = e1 x e2 and G3, counter-clockwise, is a positive turn about n as in LinuxCNC):
  base = the centre, u = (axial travel / length) n, E(phi) = cos(phi) e1 + sin(phi) e2,
  phi = phi0 + w s, and r(s) = r0 + (r1 - r0) s / length: a radius that differs at the
  end by a little (allowed up to the modal machine's tolerance) is closed by a spiral,
  so the curve ends exactly at the programmed point.

Derivatives by s (``shape``): p' = u + r' E + r w E_perp, p'' = 2 r' w E_perp - r w^2 E,
p''' = -3 r' w^2 E - r w^3 E_perp, with E_perp = dE/dphi.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

Kind = Literal["rapid", "linear", "arc", "dwell", "pause"]
PLANE_AXES = {"G17": (0, 1, 2), "G18": (2, 0, 1), "G19": (1, 2, 0)}
"""Per plane: the axes (e1, e2, n) [0 = x, 1 = y, 2 = z]; I, J, K go with x, y, z."""

Vec = tuple[float, float, float]


@dataclass(frozen=True)
class Segment:
    """One step of a program after the modal machine.

    line: the program line (1-based); kind: rapid (G0, at the jog limits), linear (G1),
    arc (G2/G3, helix when it also moves along the plane's normal), dwell (G4) or pause
    (M0, M1: the path stops there). start_m / end_m: base-frame points [m]. centre_m: the arc's
    centre in the start's plane [m]; plane: "G17", "G18" or "G19"; direction: "cw" (G2)
    or "ccw" (G3); sweep_rad: the turn, signed about the plane's normal [rad]. feed_m_s:
    the programmed feed [m/s] (None for rapids: the jog speed); dwell_s [s]; blend_m:
    the G64 P tolerance in force [m] (None under G61, exact stop). phi_start_rad /
    phi_end_rad: the wrist angle [rad] at the start and end (the A word, with a wrist),
    linear in the arc length between them; a move of the wrist alone (no xyz travel)
    runs along its turn [rad] instead, at ``feed_rad_s`` [rad/s] (G1: F read as deg/min,
    as LinuxCNC reads it for a rotary axis alone; None: the wrist's speed limit).
    optional: a pause that is M1, an optional stop (it stops only with the optional stop
    switched on when it runs).
    """

    line: int
    kind: Kind
    start_m: Vec
    end_m: Vec
    centre_m: Vec | None = None
    plane: str | None = None
    direction: Literal["cw", "ccw"] | None = None
    sweep_rad: float = 0.0
    feed_m_s: float | None = None
    dwell_s: float = 0.0
    blend_m: float | None = None
    phi_start_rad: float = 0.0
    phi_end_rad: float = 0.0
    feed_rad_s: float | None = None
    optional: bool = False

    @property
    def moves(self) -> bool:
        return self.kind in ("rapid", "linear", "arc")

    @property
    def turn_rad(self) -> float:
        """The wrist's turn over the segment [rad] (signed)."""
        return self.phi_end_rad - self.phi_start_rad

    @property
    def distance(self) -> float:
        """What the segment's profile runs along: its arc length [m], or for a turn of the
        wrist alone |turn| [rad]; 0 for dwells and pauses."""
        if not self.moves:
            return 0.0
        length = self.curve().length
        return length if length > 0 else abs(self.turn_rad)

    def curve(self) -> Curve:
        """This segment's geometry by arc length (a point for dwells and pauses); built
        once (the planner asks for it several times per segment)."""
        cached = self.__dict__.get("_curve")
        if cached is None:
            cached = self._build_curve()
            object.__setattr__(self, "_curve", cached)
        return cached

    def _build_curve(self) -> Curve:
        start, end = np.asarray(self.start_m), np.asarray(self.end_m)
        if self.kind != "arc":
            delta = end - start
            length = float(np.linalg.norm(delta)) if self.moves else 0.0
            u = delta / length if length > 0 else np.zeros(3)
            return Curve(start, u, 0.0, 0.0, np.eye(3)[0], np.eye(3)[1], 0.0, 0.0, length)
        a, b, c = PLANE_AXES[self.plane or "G17"]
        e1, e2, n = np.eye(3)[a], np.eye(3)[b], np.eye(3)[c]
        centre = np.asarray(self.centre_m)
        r0 = math.hypot(*(start - centre)[[a, b]])
        r1 = math.hypot(*(end - centre)[[a, b]])
        phi0 = math.atan2((start - centre)[b], (start - centre)[a])
        axial = float((end - start)[c])
        length = math.hypot(0.5 * (r0 + r1) * self.sweep_rad, axial)
        return Curve(
            centre + n * (start - centre)[c],
            n * axial / length,
            r0,
            (r1 - r0) / length,
            e1,
            e2,
            phi0,
            self.sweep_rad / length,
            length,
        )


@dataclass(frozen=True)
class Curve:
    """p(s) = base + u s + (r0 + dr s) E(phi0 + w s), 0 <= s <= length [m] (see module)."""

    base: np.ndarray
    u: np.ndarray
    r0: float
    dr: float
    e1: np.ndarray
    e2: np.ndarray
    phi0: float
    w: float
    length: float

    @property
    def curvature(self) -> float:
        """Largest |p''| over the curve [1/m] (the circle's or helix's 1/radius)."""
        r = max(self.r0, self.r0 + self.dr * self.length)
        return r * self.w**2 + 2.0 * abs(self.dr * self.w)

    @property
    def torsion_term(self) -> float:
        """Largest |p'''| over the curve [1/m^2]."""
        r = max(self.r0, self.r0 + self.dr * self.length)
        return r * abs(self.w) ** 3 + 3.0 * abs(self.dr) * self.w**2


def shape(
    s: np.ndarray,
    base: np.ndarray,
    u: np.ndarray,
    r0: np.ndarray,
    dr: np.ndarray,
    e1: np.ndarray,
    e2: np.ndarray,
    phi0: np.ndarray,
    w: np.ndarray,
    order: int,
) -> np.ndarray:
    """d^order p / ds^order of the curves at arc lengths ``s`` (N,), per-sample curve
    parameters (N,) or (N, 3); returns (N, 3) [m^(1 - order)]. Orders 0 to 3."""
    phi = phi0 + w * s
    cos, sin = np.cos(phi)[:, None], np.sin(phi)[:, None]
    E, E_perp = cos * e1 + sin * e2, -sin * e1 + cos * e2
    r = (r0 + dr * s)[:, None]
    dr_, w_ = dr[:, None], w[:, None]
    if order == 0:
        return base + u * s[:, None] + r * E
    if order == 1:
        return u + dr_ * E + r * w_ * E_perp
    if order == 2:
        return 2.0 * dr_ * w_ * E_perp - r * w_**2 * E
    if order == 3:
        return -3.0 * dr_ * w_**2 * E - r * w_**3 * E_perp
    raise ValueError(f"order: 0 to 3, got {order}")

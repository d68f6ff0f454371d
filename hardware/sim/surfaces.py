"""Surfaces the twin's tool tip can touch: plates fixed in the base frame or in the world
(moving in the base frame as the drone drifts), and the twin's own contact force
(MuJoCo's, the ground truth a force estimate is measured against).

A plate is a box whose top face passes through `Plate.point_m` with outward normal
`Plate.normal` (pointing towards the robot). Its contact with the tip (a small sphere on the
platform, or on the wrist with one) is a soft MuJoCo constraint with a constant impedance
d = `CONTACT_IMPEDANCE` (solimp d0 = dwidth) and solref in MuJoCo's direct format
(-k', -b'). MuJoCo's reference acceleration is a_ref = -(b'/d) v - (k'/d^2) d r and the
constraint's regularizer R = (1 - d)/d * A, with A its approximate inverse mass along the
normal (efc_diagApprox: the sum of the two bodies' body_invweight0, the world's being 0);
at rest the normal force is f = a_ref / R = k' p / ((1 - d) A) for a penetration p = -r
(mj_makeImpedance, engine_core_constraint.c; MuJoCo docs, "Solver parameters"). So
k' = k (1 - d) A and b' = b (1 - d) A give the plate's stiffness k [N/m] and damping
b [N s/m] as a force law: `direct_solref`. The friction cone is elliptic (the tip's
tangential force never exceeds mu times the normal force) with sliding friction mu.

Plain NumPy here (the config builds plates without MuJoCo); hardware.sim.mjcf writes them
and hardware.sim.twin reads the contact forces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

CONTACT_IMPEDANCE = 0.9  # solimp d of a plate's contact, constant over the penetration
TIP_RADIUS_M = 0.001  # the tip sphere: contact starts when its centre is this far out
CONTACT_GROUP = 2  # contype/conaffinity bit shared by the tip and the plates only
FIXED_IN = ("base", "world")  # where a plate stays put (Plate.fixed_in)


def _triple(name: str, values, size: int = 3) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise ValueError(f"plate {name}: must be {size} numbers, got {values!r}") from None
    if len(out) != size or not all(math.isfinite(v) for v in out):
        raise ValueError(f"plate {name}: must be {size} finite numbers, got {list(out)}")
    return out


@dataclass(frozen=True)
class Plate:
    """A flat rectangular plate, fixed in the base frame or in the world.

    point_m: a point of its touched face [m], (3,); normal: the face's outward normal,
    towards the robot (normalized here; any non-zero length), (3,), both in the base frame
    as the scene starts (see fixed_in); half_size_m:
    half its extent along the face's x and y (`frame`) [m], (2,); thickness_m: [m];
    stiffness_n_m: contact stiffness [N/m] (static: force = stiffness * penetration);
    damping_n_s_m: contact damping [N s/m]; friction: Coulomb coefficient (0: frictionless).

    fixed_in: "base" (default): the plate stays at point_m / normal in the base frame
    whatever the drone does (a plate carried by the drone, the bench). "world": a wall
    fixed in the world. point_m / normal then place it in the base frame at the first
    base pose the twin is given (`BaseMotion.position_m`, sent each tick by a hold on
    the simulated drone): the scene starts as configured, whatever the drone's hover
    point, drift or the mount are, and from then on the wall stays put in the world and
    moves in the base frame as base^-1 * (base_0 * plate) (DeltaTwin.set_base_motion);
    a base motion without a position (the level, still base between holds) puts it back
    where configured and the next pose anchors it again. So configure the wall where it
    should be relative to the robot as the hold starts (e.g. 26 mm under the tip), as
    for a plate fixed in the base.

    Raises:
        ValueError: naming the field and why (not finite, zero normal, not positive,
        fixed_in neither "base" nor "world"...).
    """

    point_m: tuple[float, float, float]
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    half_size_m: tuple[float, float] = (0.1, 0.1)
    thickness_m: float = 0.02
    stiffness_n_m: float = 1.0e4
    damping_n_s_m: float = 20.0
    friction: float = 0.5
    fixed_in: str = "base"

    def __post_init__(self) -> None:
        if self.fixed_in not in FIXED_IN:
            raise ValueError(f"plate fixed_in: must be 'base' or 'world', got {self.fixed_in!r}")
        point = _triple("point_m", self.point_m)
        normal = np.array(_triple("normal", self.normal))
        length = math.hypot(*normal)  # np.linalg.norm overflows to inf past ~1e154 each
        if length < 1e-9:
            raise ValueError(f"plate normal: must not be zero, got {normal.tolist()}")
        half = _triple("half_size_m", self.half_size_m, 2)
        if min(half) <= 0.0:
            raise ValueError(f"plate half_size_m: must be positive [m], got {list(half)}")
        for name, lowest in (
            ("thickness_m", 0.0),
            ("stiffness_n_m", 0.0),
            ("damping_n_s_m", None),
            ("friction", None),
        ):
            value = float(getattr(self, name))
            if not math.isfinite(value) or value < 0.0 or (lowest is not None and value <= 0):
                kind = "positive" if lowest is not None else "zero or positive"
                raise ValueError(f"plate {name}: must be finite and {kind}, got {value}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "point_m", point)
        object.__setattr__(self, "normal", tuple(float(v) for v in normal / length))
        object.__setattr__(self, "half_size_m", half)

    def frame(self) -> np.ndarray:
        """The plate's axes in the base frame as columns (x, y along the face, z = normal),
        (3, 3), a rotation: x is the base x projected onto the face (the base y when the
        normal is within 25 deg of the base x)."""
        z = np.array(self.normal)
        seed = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = seed - (seed @ z) * z
        x /= np.linalg.norm(x)
        return np.column_stack([x, np.cross(z, x), z])

    def height_m(self, point_m) -> np.ndarray:
        """Signed distance [m] of base-frame points (..., 3) above the face (along the
        normal; negative inside), shape (...)."""
        return (np.asarray(point_m, dtype=float) - np.array(self.point_m)) @ np.array(self.normal)

    def direct_solref(self, inverse_mass: float) -> tuple[float, float]:
        """MuJoCo's direct solref (-k', -b') giving this plate's stiffness and damping as
        a force law for a contact whose approximate inverse mass along the normal is
        `inverse_mass` [1/kg] (body_invweight0 summed): k' = k (1 - d) A, b' = b (1 - d) A
        with d = `CONTACT_IMPEDANCE` (module docstring)."""
        scale = (1.0 - CONTACT_IMPEDANCE) * float(inverse_mass)
        return -self.stiffness_n_m * scale, -self.damping_n_s_m * scale


@dataclass(frozen=True)
class TwinContact:
    """The twin's own contact force: what the tip applies on the plates, base frame.

    force_n: [N], (3,), summed over the tip's contacts (the tip pressing down on a plate
    below it gives force_n[2] < 0); point_m: where it acts [m], (3,) (the force-weighted
    mean of the contact points), None without contact; in_contact: the tip touches a plate.
    """

    force_n: np.ndarray
    point_m: np.ndarray | None
    in_contact: bool

    @classmethod
    def none(cls) -> TwinContact:
        """No contact: zero force, no point."""
        return cls(np.zeros(3), None, False)

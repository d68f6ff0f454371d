"""The compliant press: a set contact force along a direction, position across it.

An admittance on top of a position source (thesis ch. 6.3's "compliant control for safe
interactions"): the inner source gives the tip's point each tick (a fixed point, or the
hold-in-world's goal moved into the base frame through the drone's pose, app/world/hold.py),
and the press shifts it along the pressed direction ``d`` by an offset ``s`` that follows
the force error,

    ds/dt = k_a (f_set(t) - F . d),    |s| <= travel,

``k_a`` ``contact.admittance_m_per_n_s``, F the loop's force estimate (app/control/
contact.py), f_set ramped from 0 over ``RAMP_S``. Across d the inner source's point is
kept. With the servos' position loop as the spring (and the surface's in series), the
force error decays with time constant 1 / (k_a k) (k the tip's stiffness along d); a
surface that moves with the drone's drift is followed by the inner source's goal, the
offset takes up only what the drift's model misses.

Safety: a press ``presses`` (the monitor faults past ``contact.force_limit_n`` or on a
lost estimate); the offset at the end of its travel with no force ("contact lost", or
"no contact" before any) faults and holds.

``d`` is given in the base frame, or in the world frame (``frame="world"``) when the inner
source holds in the world: then it turns with the drone's attitude (the inner source's
``base_pose``) each tick.
"""

from __future__ import annotations

import math
import uuid

import numpy as np

from app.control.sources import GoalSource, Setpoint
from app.control.state import ContactReading
from app.control.touch import unit_direction

RAMP_S = 0.5  # the set force is ramped in over this [s]
CONTACT_FRACTION = 0.5  # in contact while the force along d is over this part of the set


class PressSource:
    """A press's goal source (module doc).

    inner: the source whose point is pressed from (None: hold ``start_m`` (3,) [m]);
    direction (3,), normalised, in ``frame`` ("base" or "world"); force_n: the set force
    [N] > 0; gain_m_per_n_s: k_a [m/(N s)] > 0; travel_m: the offset's bound [m] > 0;
    duration_s: end after this long (None: until stopped or the inner source ends).
    ValueError naming the field for bad values.
    """

    name = "press"
    presses = True

    def __init__(
        self,
        inner: GoalSource | None,
        start_m: np.ndarray,
        direction: object,
        force_n: float,
        gain_m_per_n_s: float,
        travel_m: float,
        frame: str = "base",
        duration_s: float | None = None,
        source_id: str | None = None,
    ) -> None:
        self.d = unit_direction(direction)
        if frame not in ("base", "world"):
            raise ValueError(f"frame: expected 'base' or 'world', got {frame!r}")
        if frame == "world" and inner is None:
            raise ValueError("frame: a direction in the world needs a hold in the world")
        for name, value in (
            ("force_n", force_n),
            ("gain_m_per_n_s", gain_m_per_n_s),
            ("travel_m", travel_m),
        ):
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {value!r}")
        if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
            raise ValueError(f"duration_s: must be a finite number > 0, got {duration_s!r}")
        self.inner, self.frame = inner, frame
        self.start = np.asarray(start_m, dtype=float).copy()
        self.force, self.gain, self.travel = float(force_n), float(gain_m_per_n_s), float(travel_m)
        self.duration_s = duration_s
        self.source_id = source_id or f"press-{uuid.uuid4().hex[:8]}"
        self.t_s = 0.0
        self.s = 0.0  # the offset along d [m]
        self.f = math.nan  # this tick's force along d [N]
        self.in_contact = False
        self.had_contact = False
        self._reading: ContactReading | None = None

    def observe_contact(
        self, reading: ContactReading, point_m: np.ndarray, joints_rad: np.ndarray | None = None
    ) -> None:
        """This tick's force estimate (app/control/contact.py)."""
        self._reading = reading

    @property
    def base_pose(self) -> object | None:
        """The base's pose in the world this tick, from a hold in the world (else None)."""
        return getattr(self.inner, "base_pose", None)

    def direction_base(self) -> np.ndarray:
        """The pressed direction in the base frame now (3,)."""
        if self.frame == "base":
            return self.d
        base = self.base_pose
        if base is None:
            return np.full(3, np.nan)
        return np.asarray(base.rotation).T @ self.d  # type: ignore[attr-defined]

    def set_force_n(self) -> float:
        """The set force now [N] (ramped in over RAMP_S)."""
        return self.force * min(1.0, self.t_s / RAMP_S)

    def next(self, dt_s: float) -> Setpoint:
        self.t_s += dt_s
        inner = self._inner_setpoint(dt_s)
        if inner.fault is not None or inner.point_m is None:
            return inner
        d = self.direction_base()
        if not np.isfinite(d).all():
            return Setpoint(warning="press: no drone attitude yet: holding", phase="press")
        reading = self._reading
        f = float(np.dot(reading.force_n, d)) if reading is not None and reading.valid else math.nan
        self.f = f
        wanted = self.set_force_n()
        if math.isfinite(f) and reading is not None and reading.fresh:
            self.in_contact = f >= CONTACT_FRACTION * self.force
            self.had_contact = self.had_contact or self.in_contact
            self.s += self.gain * (wanted - f) * dt_s
        if abs(self.s) >= self.travel:
            self.s = math.copysign(self.travel, self.s)
            if not self.in_contact and self.t_s > RAMP_S:
                what = "contact lost" if self.had_contact else "no contact"
                return Setpoint(
                    fault=(
                        f"{what}: {0.0 if not math.isfinite(f) else f:.2f} N along the press "
                        f"after {self.travel * 1e3:.0f} mm (contact.press_travel_m)"
                    ),
                    phase="press",
                    finished=True,
                )
        finished = inner.finished or (self.duration_s is not None and self.t_s >= self.duration_s)
        extra = dict(inner.extra or {})
        extra.update(
            force_along_n=None if not math.isfinite(f) else f,
            force_set_n=wanted,
            press_offset_m=self.s,
        )
        return Setpoint(
            point_m=inner.point_m + d * self.s,
            goal_m=inner.goal_m if inner.goal_m is not None else inner.point_m,
            phi_rad=inner.phi_rad,
            goal_phi_rad=inner.goal_phi_rad,
            phase=inner.phase or "press",
            finished=finished,
            extra=extra,
        )

    def _inner_setpoint(self, dt_s: float) -> Setpoint:
        if self.inner is None:
            return Setpoint(point_m=self.start, goal_m=self.start, phase="press")
        return self.inner.next(dt_s)

"""Touch: a guarded move towards a surface that stops at a set force.

The tip moves from where it is along a unit direction ``d`` (base frame) at a set speed
(reached at ``ACCELERATION_M_S2``). Each tick the loop hands the source its force
estimate (app/control/contact.py); with f = F . d the force the tip pushes along d:

- approach: until f >= ``detect_n`` (contact), or the travel ends (outcome "no contact");
- press: on at the same speed, logging (x, f) with x the measured tip along d, until
  f >= ``force_n``; then the point is held (the force stays, the servos hold position);
- dwell ``DWELL_S`` for the force to settle, then retract to ``retract_m`` short of the
  surface found (0: stay pressed; the command stands past the surface by the servos'
  give under the force, so backing off the command by retract_m would not lift the tip).

Contact is seen on the force tared while the tip moves freely: the mean force along d over
the approach at full speed (the gearboxes' friction and the unmodelled accelerations read
as a small force while moving) is taken off before the threshold is compared. Once on the
surface the joints stand, that bias is gone, and the set force is compared as read.

The contact point is where the surface starts. The measured tip is quantized by the
encoders (about 0.2 mm at the tip), so the rise of the force is fitted against the
commanded travel s, which is smooth: f = k (s - s0) by least squares over the press (the
servos' stiffness and the surface's in series), s0 its zero; the commanded point leads
the measured one by the following lag, measured over the approach as the mean of
s - x (x the measured tip along d); the surface is at x0 = s0 - lag. Without enough
samples, the measured tip when contact was seen. A force past
``contact.force_limit_n`` faults (the monitor: a touch ``presses``). Results go out as
``touch_result`` (app/control/state.py ``TouchResult``) each tick.
"""

from __future__ import annotations

import math
import uuid

import numpy as np

from app.control.sources import Setpoint
from app.control.state import ContactReading, TouchResult

ACCELERATION_M_S2 = 0.5  # speed ramp at the start and of the retract [m/s^2]
DWELL_S = 0.2  # held at the set force before the result is final [s]
MIN_FIT_SAMPLES = 4
TARE_SAMPLES = 100  # the approach's last samples at speed the tare, lag and fit use
TARE_SETTLE = 10  # the first samples at speed always go into the tare
HINGE_CANDIDATES = 400  # where the force's rise may start, tried along the fitted span


def unit_direction(direction: object, name: str = "direction") -> np.ndarray:
    """``direction`` (3,) as a unit vector; ValueError naming ``name`` when it is not
    three finite numbers of non-zero length."""
    try:
        d = np.asarray(direction, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected three finite numbers, got {direction!r}") from None
    if d.shape != (3,) or not np.isfinite(d).all():
        raise ValueError(f"{name}: expected three finite numbers, got {direction!r}")
    largest = float(np.abs(d).max())
    if largest == 0.0:
        raise ValueError(f"{name}: a direction cannot be zero")
    scaled = d / largest  # the norm of a huge direction (1e200 each) would overflow
    size = largest * float(np.linalg.norm(scaled))
    if size < 1e-9:
        raise ValueError(f"{name}: a direction cannot be zero")
    return scaled / float(np.linalg.norm(scaled))


class TouchSource:
    """A touch's goal source (module doc). ``start_m`` (3,) [m] where it starts (the
    commanded tip), ``direction`` (3,) (normalised), ``speed_m_s`` > 0, ``force_n`` the
    set force [N], ``detect_n`` the contact threshold [N] (< force_n), ``max_travel_m``
    [m], ``retract_m`` >= 0 [m]. ValueError naming the field for bad values."""

    name = "touch"
    presses = True

    def __init__(
        self,
        start_m: np.ndarray,
        direction: object,
        speed_m_s: float,
        force_n: float,
        detect_n: float,
        max_travel_m: float,
        retract_m: float = 0.0,
        source_id: str | None = None,
    ) -> None:
        self.d = unit_direction(direction)
        for name, value in (
            ("speed_m_s", speed_m_s),
            ("force_n", force_n),
            ("detect_n", detect_n),
            ("max_travel_m", max_travel_m),
        ):
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {value!r}")
        if not (math.isfinite(retract_m) and retract_m >= 0):
            raise ValueError(f"retract_m: must be a finite number >= 0, got {retract_m!r}")
        if detect_n >= force_n:
            raise ValueError(
                f"force_n: {force_n:g} N is not above the contact threshold {detect_n:g} N"
            )
        self.start = np.asarray(start_m, dtype=float).copy()
        self.speed, self.force, self.detect = float(speed_m_s), float(force_n), float(detect_n)
        self.max_travel, self.retract = float(max_travel_m), float(retract_m)
        self.source_id = source_id or f"touch-{uuid.uuid4().hex[:8]}"
        self.phase = "approach"
        self.s = 0.0  # commanded travel along d [m]
        self.v = 0.0  # commanded speed along d [m/s]
        self.t_s = 0.0
        self._dwell_s = 0.0
        self._back_to = 0.0  # the travel the retract ends at [m]
        self.reached_m = 0.0  # the furthest travel commanded [m]
        self._f = 0.0  # this tick's force along d [N]
        self._reading: ContactReading | None = None
        self._point = np.full(3, np.nan)
        self._at_contact: np.ndarray | None = None  # the measured tip when contact began
        self._joints: np.ndarray | None = None
        self._joints_at_contact = np.full(3, np.nan)
        self._held_force: np.ndarray | None = None
        self._press_s: list[float] = []  # commanded travel over the press [m]
        self._press_f: list[float] = []  # tared force along d over the press [N]
        self._free_f: list[float] = []  # force along d over the approach at speed [N]
        self._free_lag: list[float] = []  # s - x over the approach at speed [m]
        self._free_s: list[float] = []  # commanded travel over the approach at speed [m]
        self._tare_f: list[float] = []  # the free force samples the tare averages [N]
        self._fitted: np.ndarray | None = None  # the contact point, once fitted
        self.tare_n = 0.0
        self.peak_n = 0.0
        self.outcome = "touching"

    # ---- fed by the loop ----
    def observe_contact(
        self, reading: ContactReading, point_m: np.ndarray, joints_rad: np.ndarray | None = None
    ) -> None:
        """This tick's force estimate, measured tip (3,) [m] and the legs' joints as read
        (3,) [rad] (app/control/contact.py)."""
        self._reading, self._point = reading, np.asarray(point_m, dtype=float)
        self._joints = None if joints_rad is None else np.asarray(joints_rad, dtype=float)
        f = float(np.dot(reading.force_n, self.d)) if reading.valid else math.nan
        self._f = f
        if math.isfinite(f):
            self.peak_n = max(self.peak_n, f)

    def next(self, dt_s: float) -> Setpoint:
        self.t_s += dt_s
        if self._reading is not None and not self._reading.fresh:
            return self._setpoint()  # an old force: command nothing new from it, wait
        x = float(np.dot(self._point - self.start, self.d))
        f = self._f - self.tare_n
        if self.phase == "approach":
            # contact is judged on the tared force only once the tare is taken (a touch
            # started while the arm settles reads its deceleration as a force)
            tared = len(self._tare_f) >= TARE_SETTLE
            if math.isfinite(f) and (f >= self.detect and tared or self._f >= self.force):
                self.phase = "press"
                self._at_contact = self._point.copy()
                if self._joints is not None:
                    self._joints_at_contact = self._joints.copy()
            elif self.s >= self.max_travel:
                self.outcome = "no contact"
                return self._setpoint(finished=True)
            elif self.v >= self.speed and math.isfinite(f) and math.isfinite(x):
                self._free_s.append(self.s)  # at speed: what the fit and the lag use
                self._free_f.append(self._f)
                self._free_lag.append(self.s - x)
                # the tare follows the free force, not a slow rise on a soft surface
                if len(self._free_s) <= TARE_SETTLE or f < self.detect / 2:
                    self._tare_f.append(self._f)
                    self.tare_n = float(np.mean(self._tare_f[-TARE_SAMPLES:]))
        if self.phase == "press":
            if math.isfinite(self._f):
                self._press_s.append(self.s)
                self._press_f.append(self._f)
            # the tip stands on the surface: the set force is compared as read
            if math.isfinite(self._f) and self._f >= self.force:
                self.phase, self.v = "dwell", 0.0
            elif self.s >= self.max_travel:
                self.outcome = "contact"  # the force set was not reached within the travel
                return self._setpoint(finished=True)
        if self.phase in ("approach", "press"):
            self.v = min(self.speed, self.v + ACCELERATION_M_S2 * dt_s)
            self.s = min(self.max_travel, self.s + self.v * dt_s)
            self.reached_m = self.s
        elif self.phase == "dwell":
            self._dwell_s += dt_s
            if self._dwell_s >= DWELL_S:
                self.outcome = "contact"
                if self._reading is not None:  # the force it stood at, before any retract
                    self._held_force = np.asarray(self._reading.force_n, dtype=float).copy()
                self.reached_m = self.s
                if self.retract <= 0:
                    return self._setpoint(finished=True)
                self.phase = "retract"
                # back to retract_m short of the surface (the command stands past it by the
                # servos' give under the force), not retract_m short of the command
                surface = float(np.dot(self.contact_point() - self.start, self.d))
                if not math.isfinite(surface):
                    surface = self.s
                self._back_to = max(0.0, min(self.s, surface - self.retract))
        if self.phase == "retract":
            self.v = min(self.speed, self.v + ACCELERATION_M_S2 * dt_s)
            self.s = max(self._back_to, self.s - self.v * dt_s)
            if self.s <= self._back_to + 1e-12:
                return self._setpoint(finished=True)
        return self._setpoint()

    # ---- results ----
    def contact_point(self) -> np.ndarray:
        """Where the surface starts (3,) [m] (module doc); NaN without contact. Fitted once
        the press has ended (until then: the measured tip when contact was seen)."""
        if self._at_contact is None:
            return np.full(3, np.nan)
        if self._fitted is not None:
            return self._fitted
        if self.phase in ("approach", "press"):
            return self._at_contact.copy()
        x_contact = float(np.dot(self._at_contact - self.start, self.d))
        x0 = x_contact
        s0 = self._rise_start()
        if s0 is not None:
            # the lag over the approach before the rise (then the tip stands on the surface)
            pairs = zip(self._free_s, self._free_lag, strict=True)
            lags = [lag for s, lag in pairs if s < s0]
            if lags:
                x0 = s0 - float(np.mean(lags[-TARE_SAMPLES:]))
        self._fitted = self._at_contact + self.d * (x0 - x_contact)
        return self._fitted

    def _rise_start(self) -> float | None:
        """The commanded travel s0 [m] where the force starts to rise: the hinge
        f = c + k max(0, s - s0) fitted by least squares to the force as read over the
        approach's last samples at speed and the press (s0 tried along their span; c, the
        bias read while moving, and k solved for each). None with too few samples or no
        rise.

        The bias is taken to stay as the force rises, as on the twin (the hinge finds its
        plate to 0.03 mm); were it to vanish at contact, the point would come out bias / k
        late (~0.3 mm for 0.6 N against the servos' ~2,000 N/m): the uncertainty a real
        servo's touch carries until measured (docs/contact.md)."""
        if len(self._press_s) < MIN_FIT_SAMPLES:
            return None
        travel = np.asarray(self._free_s[-TARE_SAMPLES:] + self._press_s)
        force = np.asarray(self._free_f[-TARE_SAMPLES:] + self._press_f)
        ones = np.ones_like(travel)
        best: tuple[float, float] | None = None
        for s0 in np.linspace(travel[0], travel[-1], HINGE_CANDIDATES):
            hinge = np.maximum(0.0, travel - s0)
            if not hinge.any() or hinge.all():
                continue
            design = np.column_stack([ones, hinge])
            (c, k), *_ = np.linalg.lstsq(design, force, rcond=None)
            if k <= 0:
                continue
            error = float(np.sum((force - c - k * hinge) ** 2))
            if best is None or error < best[0]:
                best = (error, float(s0))
        return None if best is None else best[1]

    @property
    def touch_result(self) -> TouchResult:
        """How far it is, as the loop publishes it ("touching" until it ends)."""
        force = self._reading.force_n if self._reading is not None else np.full(3, np.nan)
        if self._held_force is not None:
            force = self._held_force
        return TouchResult(
            outcome=self.outcome,
            contact_point_m=self.contact_point(),
            force_n=np.asarray(force, dtype=float),
            peak_force_n=self.peak_n,
            travel_m=max(self.reached_m, self.s),
            direction=self.d,
            source_id=self.source_id,
            joints_at_contact_rad=self._joints_at_contact,
        )

    def _setpoint(self, finished: bool = False) -> Setpoint:
        point = self.start + self.d * self.s
        extra = {"force_along_n": None if not math.isfinite(self._f) else self._f}
        return Setpoint(
            point_m=point, finished=finished, goal_m=point, phase=self.phase, extra=extra
        )

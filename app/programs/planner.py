"""Segments to one timed path: each move from rest to rest along its curve, dwells held
in place; the result is a `TimedPath` (app/runs/trajectories.py), so the run manager can
plan its approach and stop and run it like any other test path.

Corners: exact stop (G61, the default), or under G64 P blended by overlapping the two
moves in time: the next move starts while the last one finishes, and the point is their
sum, p(t) = p_a(t) + (p_b(t) - corner). The overlap lasts T_o = min(Tj_a, Tj_b, the time
each move takes to cover P / 2 from rest), so:

- the path stays within P of the corner: |p - corner| <= d_a + d_b <= P;
- the speed stays within the larger cruise speed (in each move's jerk phase
  v(T_o - tau) + v(tau) <= v(T_o) <= V);
- the acceleration within the larger limit: J_a (T_o - tau) + J_b tau <= J T_o <= A;
- the jerk: the two jerk phases add, up to 2 J cos(theta / 2) for a turn of theta (2 J
  where a move runs on in the same direction). Halving each move's jerk instead would
  keep J but lengthen every move by more than the overlap saves (tried: a blended square
  took longer than the exact-stop one); the joint checks see the blend as planned.

No stop at a blended corner; a dwell, a pause or a G61 move between two moves stops.

Limits per segment:

- rapids (G0): the jog limits (``[jog]``: speed, acceleration, jerk; per axis there,
  applied to the path's magnitude here, which is never more per axis);
- feed moves (G1/G2/G3): speed the programmed F, acceleration and jerk ``[programs]``;
- on arcs the acceleration is shared: A / sqrt(2) along the path and v^2 / rho <= A /
  sqrt(2) across it (so |a| <= A), the jerk likewise; and the loop's chord from one
  sample to the next, kappa (v dt)^2 / 8, stays within ``chord_tolerance_m``
  (the arc is discretised by the loop's own period, to the stated tolerance);
- the wrist (A words): phi runs linearly in the arc length, phi = phi0 + k s with k =
  turn / length, so its speed, acceleration and jerk are k times the path's; the path's
  limits are lowered to the wrist's divided by k (``wrist_*``), and a turn of the wrist
  alone runs along its angle within the wrist's limits (G1: and its F in deg/min).
  Blends add the two turns as they add the two moves, within the larger of their peaks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from app.programs.profile import Profile, evaluate, rest_to_rest
from app.programs.segments import Segment, shape

SQRT2 = math.sqrt(2.0)


@dataclass(frozen=True)
class PlanLimits:
    """rapid_*: jog speed [m/s], acceleration [m/s^2], jerk [m/s^3] for G0; feed_*: path
    acceleration and jerk for G1-G3; chord_tolerance_m [m]; period_s: the loop period [s];
    wrist_*: the wrist's speed [rad/s], acceleration [rad/s^2] and jerk [rad/s^3] (None:
    no wrist, and a segment that turns it cannot be planned)."""

    rapid_speed: float
    rapid_accel: float
    rapid_jerk: float
    feed_accel: float
    feed_jerk: float
    chord_tolerance_m: float
    period_s: float
    wrist_speed: float | None = None
    wrist_accel: float | None = None
    wrist_jerk: float | None = None


WRIST_MARGIN = 1.0 - 1e-9  # the wrist's peaks stay under its limits through rounding


def segment_limits(segment: Segment, limits: PlanLimits) -> tuple[float, float, float]:
    """(speed [m/s], tangential acceleration [m/s^2], jerk [m/s^3]) for one move, within
    the wrist's limits when it turns (per radian for a turn of the wrist alone).

    Raises:
        ValueError: a segment that turns the wrist without wrist limits.
    """
    speed, accel, jerk = _path_limits(segment, limits)
    turn = abs(segment.turn_rad)
    if turn == 0.0:
        return speed, accel, jerk
    wrist = (limits.wrist_speed, limits.wrist_accel, limits.wrist_jerk)
    if None in wrist:
        raise ValueError(f"line {segment.line}: the segment turns the wrist, and none is set up")
    ws, wa, wj = (float(v) * WRIST_MARGIN for v in wrist)  # type: ignore[arg-type]
    length = segment.curve().length
    if length <= 0.0:  # the wrist alone: along its angle
        feed = ws if segment.kind == "rapid" else min(ws, segment.feed_rad_s or ws)
        return feed, wa, wj
    k = turn / length  # rad per metre
    return min(speed, ws / k), min(accel, wa / k), min(jerk, wj / k)


def _path_limits(segment: Segment, limits: PlanLimits) -> tuple[float, float, float]:
    if segment.kind == "rapid":
        return limits.rapid_speed, limits.rapid_accel, limits.rapid_jerk
    speed = float(segment.feed_m_s or 0.0)
    accel, jerk = limits.feed_accel, limits.feed_jerk
    if segment.kind != "arc":
        return speed, accel, jerk
    curve = segment.curve()
    kappa, kappa3 = curve.curvature, curve.torsion_term
    accel, jerk = accel / SQRT2, jerk / 2.0
    caps = [
        speed,
        math.sqrt(accel / kappa),  # centripetal
        math.sqrt(8.0 * limits.chord_tolerance_m / kappa) / limits.period_s,  # chord
        (0.5 * jerk / kappa3) ** (1.0 / 3.0) if kappa3 > 0 else math.inf,  # v^3 |p'''|
        0.5 * jerk / (3.0 * kappa * accel),  # 3 |p''| v a
    ]
    return min(caps), accel, jerk


@dataclass(frozen=True)
class ProgramPath:
    """A planned program: segments timed end to end, t = 0 at the first segment's start.

    A `TimedPath`: ``derivatives(t, order)`` (orders 0-3, (*,) -> (*, 3) [m/s^order]),
    ``duration_s``, ``peaks()``, ``feedforward``; plus ``line_at(t)`` (the program line
    at each time) and ``start_s`` (each segment's start time). The wrist (A words):
    ``moves_wrist``, ``phi_at(t)``, ``wrist(t, orders)`` and ``phi_peak_speed()``, as a
    run's fourth axis (app/runs/trajectories.py PlannedRun).
    """

    phi_field = "gcode"  # what a run names when the wrist cannot follow the program

    segments: tuple[Segment, ...]
    profiles: tuple[Profile, ...]
    overlaps_s: tuple[float, ...] = ()
    feedforward: bool = False
    # how a run of it starts to play (app/link/paths.py Playback): the feed override
    # (0.1 to 1.0) and whether M1 stops
    feed_override: float = 1.0
    optional_stop: bool = False

    def from_line(self, line: int) -> ProgramPath:
        """The program from line ``line`` (1-based) on: its segments from the first one on
        that line or after, timed as planned (each move runs from rest, a blend into the
        first one is left out); its start is that segment's start point. ValueError
        naming ``start_line`` when no move, dwell or pause is on that line or after."""
        first = next((i for i, s in enumerate(self.segments) if s.line >= line), None)
        if first is None:
            raise ValueError(f"start_line: no move, dwell or pause on line {line} or after it")
        return replace(
            self,
            segments=self.segments[first:],
            profiles=self.profiles[first:],
            overlaps_s=self.overlaps_s[first:],
        )

    @cached_property
    def start_s(self) -> np.ndarray:
        """Each segment's start time [s]: the last one's end less their overlap (G64)."""
        durations = np.array([p.duration for p in self.profiles])
        overlaps = np.zeros(len(durations))
        overlaps[: len(self.overlaps_s)] = self.overlaps_s  # overlap of i with i + 1
        return np.concatenate([[0.0], np.cumsum(durations - overlaps)[:-1]])

    @cached_property
    def end_s(self) -> np.ndarray:
        """Each segment's end time [s]."""
        return self.start_s + np.array([p.duration for p in self.profiles])

    @property
    def duration_s(self) -> float:
        return float(self.end_s[-1]) if self.profiles else 0.0

    @property
    def length_m(self) -> float:
        return float(sum(s.curve().length for s in self.segments if s.moves))

    @cached_property
    def _table(self) -> dict[str, np.ndarray]:
        curves = [s.curve() for s in self.segments]
        table = {
            name: np.array([getattr(c, name) for c in curves])
            for name in ("base", "u", "r0", "dr", "e1", "e2", "phi0", "w")
        }
        for name in ("distance", "speed", "jerk", "tj", "ta", "tv"):
            table[name] = np.array([getattr(p, name) for p in self.profiles])
        table["line"] = np.array([s.line for s in self.segments])
        table["phi_start"] = np.array([s.phi_start_rad for s in self.segments], dtype=np.float64)
        table["phi_end"] = np.array([s.phi_end_rad for s in self.segments], dtype=np.float64)
        distance = table["distance"]
        turn = table["phi_end"] - table["phi_start"]
        table["phi_per_s"] = np.divide(
            turn, distance, out=np.zeros_like(turn), where=distance > 0
        )  # dphi / ds along each segment's profile
        table["end"] = np.array([s.end_m for s in self.segments], dtype=np.float64)
        return table

    def index_at(self, t: np.ndarray) -> np.ndarray:
        """Segment index at times ``t`` (*,) [s] (clamped to the first and last)."""
        k = np.searchsorted(self.start_s, np.asarray(t, dtype=np.float64), side="right") - 1
        return np.clip(k, 0, len(self.segments) - 1)

    def line_at(self, t: np.ndarray) -> np.ndarray:
        """Program line (1-based) at times ``t`` (*,) [s]."""
        return self._table["line"][self.index_at(t)]

    def lines_between(self, t0_s: float, t1_s: float) -> list[int]:
        """Program lines (1-based) met from time ``t0_s`` to ``t1_s`` [s], in order: the
        line at each end and every line between, so a late tick that crosses a short
        line whole (a 0.1 s rapid inside a 150 ms stall) still meets it."""
        k0, k1 = (int(k) for k in self.index_at(np.array([t0_s, t1_s])))
        return [int(v) for v in self._table["line"][k0 : k1 + 1]]

    def evaluate(self, t: np.ndarray, orders: tuple[int, ...]) -> list[np.ndarray]:
        """d^k p / dt^k for each k in ``orders`` (0-3) at times ``t`` (N,): each (N, 3).

        In a G64 overlap the segment before adds its motion (see the module)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        k = self.index_at(t)
        out = self._segment(k, t, orders)
        before = k - 1
        blending = np.flatnonzero((before >= 0) & (t < self.end_s[np.maximum(before, 0)]))
        if blending.size:
            previous = self._segment(before[blending], t[blending], orders)
            corner = self._table["end"][before[blending]]
            for value, extra, order in zip(out, previous, orders, strict=True):
                value[blending] += extra - (corner if order == 0 else 0.0)
        return out

    def _segment(self, k: np.ndarray, t: np.ndarray, orders: tuple[int, ...]) -> list[np.ndarray]:
        """Segment ``k``'s own motion at times ``t`` (each (N,))."""
        tab = {name: values[k] for name, values in self._table.items()}
        tau = t - self.start_s[k]
        s, sd, sdd, sddd = evaluate(
            tau, tab["distance"], tab["speed"], tab["jerk"], tab["tj"], tab["ta"], tab["tv"]
        )
        geometry = [tab[n] for n in ("base", "u", "r0", "dr", "e1", "e2", "phi0", "w")]
        need = max(orders)
        p = [shape(s, *geometry, i) for i in range(need + 1)]  # type: ignore[call-arg]
        sd_, sdd_, sddd_ = sd[:, None], sdd[:, None], sddd[:, None]
        chain = {
            0: lambda: p[0],
            1: lambda: p[1] * sd_,
            2: lambda: p[2] * sd_**2 + p[1] * sdd_,
            3: lambda: p[3] * sd_**3 + 3.0 * p[2] * sd_ * sdd_ + p[1] * sddd_,
        }
        return [chain[order]() for order in orders]

    @property
    def moves_wrist(self) -> bool:
        """Some segment turns the wrist (an A word changed phi)."""
        return any(s.turn_rad != 0.0 for s in self.segments)

    def wrist(self, t: np.ndarray, orders: tuple[int, ...]) -> list[np.ndarray]:
        """d^k phi / dt^k for each k in ``orders`` (0-2) at times ``t`` (N,): each (N,)
        [rad/s^k]; in a G64 overlap the turns add as the moves do."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if not self.segments:
            return [np.zeros(len(t)) for _ in orders]
        k = self.index_at(t)
        out = self._turn(k, t, orders)
        before = k - 1
        blending = np.flatnonzero((before >= 0) & (t < self.end_s[np.maximum(before, 0)]))
        if blending.size:
            previous = self._turn(before[blending], t[blending], orders)
            corner = self._table["phi_end"][before[blending]]
            for value, extra, order in zip(out, previous, orders, strict=True):
                value[blending] += extra - (corner if order == 0 else 0.0)
        return out

    def _turn(self, k: np.ndarray, t: np.ndarray, orders: tuple[int, ...]) -> list[np.ndarray]:
        """Segment ``k``'s own phi and its derivatives at times ``t`` (each (N,))."""
        tab = {name: values[k] for name, values in self._table.items()}
        tau = t - self.start_s[k]
        s = evaluate(
            tau, tab["distance"], tab["speed"], tab["jerk"], tab["tj"], tab["ta"], tab["tv"]
        )
        rate = tab["phi_per_s"]
        return [tab["phi_start"] + rate * s[0] if o == 0 else rate * s[o] for o in orders]

    def phi_at(self, t: np.ndarray) -> np.ndarray:
        """The wrist angle phi [rad] at times ``t`` (*) [s], shape (*)."""
        t = np.asarray(t, dtype=np.float64)
        return self.wrist(t.ravel(), (0,))[0].reshape(t.shape)

    def phi_peak_speed(self) -> float:
        """Bound of |dphi/dt| [rad/s]: the largest segment's (a blend stays within it)."""
        if not self.segments:
            return 0.0
        speeds = np.abs(self._table["phi_per_s"]) * self._table["speed"]
        return float(speeds.max())

    def derivatives(self, t: np.ndarray, order: int) -> np.ndarray:
        """d^order p / dt^order at times ``t`` (*,), shape (*, 3) [m/s^order]."""
        t = np.asarray(t, dtype=np.float64)
        return self.evaluate(t.ravel(), (order,))[0].reshape(*t.shape, 3)

    def peaks(self) -> tuple[float, float, float]:
        """Bounds of the path's speed [m/s], acceleration [m/s^2] and jerk [m/s^3]."""
        if not self.segments:
            return 0.0, 0.0, 0.0
        speed = accel = jerk = 0.0
        for segment, profile in zip(self.segments, self.profiles, strict=True):
            curve = segment.curve()
            if curve.length <= 0.0:  # dwells, pauses, turns of the wrist alone: no travel
                continue
            v, a = profile.speed, profile.peak_acceleration
            kappa = curve.curvature
            speed = max(speed, v)
            accel = max(accel, a + v * v * kappa)
            blended = 2.0 if segment.blend_m is not None else 1.0
            jerk = max(
                jerk, blended * (profile.jerk + 3.0 * kappa * v * a + v**3 * curve.torsion_term)
            )
        return speed, accel, jerk

    def sample_times(self, dt_s: float) -> np.ndarray:
        """Times every ``dt_s`` from 0 to the end, the end included (N,) [s]."""
        count = math.ceil(self.duration_s / dt_s - 1e-9) + 1
        return np.minimum(np.arange(count) * dt_s, self.duration_s)


def _overlap(a: Segment, pa: Profile, b: Segment, pb: Profile) -> float:
    """How long move ``b`` may start before move ``a`` ends (0: exact stop)."""
    if not (a.moves and b.moves) or a.blend_m is None or b.blend_m is None:
        return 0.0
    if a.curve().length <= 0.0 or b.curve().length <= 0.0:  # a turn of the wrist alone
        return 0.0
    tolerance = min(a.blend_m, b.blend_m)
    # covering tolerance / 2 from rest in the jerk phase: J T^3 / 6 = tolerance / 2
    reach = [(3.0 * tolerance / p.jerk) ** (1.0 / 3.0) for p in (pa, pb)]
    return float(min(pa.tj, pb.tj, *reach))


def plan_program(segments: list[Segment], limits: PlanLimits) -> ProgramPath:
    """Time every segment (see module); dwells last their P, pauses nothing.

    Raises:
        ValueError: a limit that is not finite and > 0.
    """
    profiles: list[Profile] = []
    for segment in segments:
        if segment.moves:
            profiles.append(rest_to_rest(segment.distance, *segment_limits(segment, limits)))
        else:
            profiles.append(Profile(0.0, 0.0, limits.feed_jerk, 0.0, 0.0, segment.dwell_s))
    overlaps = tuple(
        _overlap(segments[i], profiles[i], segments[i + 1], profiles[i + 1])
        for i in range(len(segments) - 1)
    )
    return ProgramPath(tuple(segments), tuple(profiles), overlaps)

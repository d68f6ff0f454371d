"""A checked timed path as data, and the goal source that plays it on the robot node.

The station plans and checks a run (a sinusoid, a chirp, a G-code program: app/runs/,
app/programs/) and sends the robot node its samples, one per loop period, not code: the
node plays them (:class:`PathSource`) and still gates every setpoint. Between samples
(a late tick) a point is interpolated linearly; at a sample it is the planned point.

A path's time runs at a rate k (:class:`Playback`): 1 as planned, the feed override
(0.1 to 1.0: a path is checked at 100 %, never played faster), 0 paused. k moves
towards its target at a bounded slew, so the setpoint stays on the checked path (only
its timing changes) with an acceleration at most ``EXTRA_ACCEL_M_S2`` over the planned
one (k^2 a + v dk/dt, k <= 1). A pause stops along the path; a single step stops at
the end of a program line; an M0 (and an M1 with the optional stop on) stops at its
line's time, where the planned path is at rest.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.control.errors import MotionRefused
from app.control.sources import Progress, Setpoint
from app.control.state import FeedState

MAX_SAMPLES = 2_000_000  # a bound on what a node takes (runs.max_samples is far below)
FEED_MIN = 0.1  # the lowest feed override (below: pause)
FEED_MAX = 1.0  # a path is checked at 100 % feed: never played faster
MAX_SLEW_PER_S = 2.0  # the fastest the rate k changes [1/s]: 100 % to stand in 0.5 s
EXTRA_ACCEL_M_S2 = 0.5  # bound of the acceleration a change of rate adds, |v| dk/dt [m/s^2]
EPS_S = 1e-9


@dataclass(frozen=True)
class SampledPath:
    """A timed path sampled at ``period_s`` [s]: sample k is at t = k * period_s, the
    last at or just past its end, ``duration_s`` [s] (the path has ended there).

    points_m: (n, 3) the tool tip [m], base frame; phi_rad: (n,) the wrist angle [rad],
    NaN where the path leaves the wrist alone (or None: it never turns it); phases: the
    phase names (approach, timed, stop, ...) and phase_index: (n,) the index of each
    sample's; lines: (n,) a G-code program's line at each sample, -1 where none (None:
    not a program); lead_s: the point commanded is this far ahead of the goal shown
    (feed-forward for the servos' lag) [s], and commanded_m: (n, 3) that point at each
    sample (None: interpolated from points_m); approach_s / timed_s: the approach's length
    and the timed part's (a run's progress) [s]; name: the loop's mode while it plays.
    """

    period_s: float
    duration_s: float
    points_m: np.ndarray
    phases: tuple[str, ...]
    phase_index: np.ndarray
    phi_rad: np.ndarray | None = None
    lines: np.ndarray | None = None
    commanded_m: np.ndarray | None = None
    lead_s: float = 0.0
    approach_s: float = 0.0
    timed_s: float = 0.0
    name: str = "test"
    spans: np.ndarray | None = None
    pauses: np.ndarray | None = None

    def __post_init__(self) -> None:
        points = np.asarray(self.points_m, dtype=float)
        n = len(points)
        if not (math.isfinite(self.period_s) and self.period_s > 0):
            raise ValueError(f"period_s: must be a positive number, got {self.period_s}")
        if points.ndim != 2 or points.shape[1] != 3 or not 2 <= n <= MAX_SAMPLES:
            raise ValueError(f"points_m: expected (n, 3) with 2 <= n <= {MAX_SAMPLES}")
        if not np.isfinite(points).all():
            raise ValueError("points_m: every point must be finite")
        for name in ("phase_index", "phi_rad", "lines"):
            values = getattr(self, name)
            if values is not None and np.shape(values) != (n,):
                raise ValueError(f"{name}: expected {n} values, one per sample")
        commanded = self.commanded_m
        if commanded is not None and (
            np.shape(commanded) != (n, 3) or not np.isfinite(commanded).all()
        ):
            raise ValueError(f"commanded_m: expected {n} finite points, one per sample")
        index = np.asarray(self.phase_index)
        if n and (index.min() < 0 or index.max() >= len(self.phases)):
            raise ValueError("phase_index: an index names no phase")
        last_s = (n - 1) * self.period_s
        if not (math.isfinite(self.duration_s) and 0 < self.duration_s <= last_s + 1e-9):
            raise ValueError(f"duration_s: must be in (0, {last_s}] (the last sample's time)")
        if not (math.isfinite(self.lead_s) and self.lead_s >= 0):
            raise ValueError(f"lead_s: must be >= 0, got {self.lead_s}")
        for name in ("spans", "pauses"):
            table = getattr(self, name)
            if table is None:
                continue
            table = np.asarray(table, dtype=float)
            if table.size == 0:  # none (an empty list crosses the link without its shape)
                table = table.reshape(0, 3)
                object.__setattr__(self, name, table)
            if table.ndim != 2 or table.shape[1] != 3 or not np.isfinite(table).all():
                raise ValueError(f"{name}: expected rows of 3 finite numbers")
            times = table[:, 1:] if name == "spans" else table[:, :1]
            if len(table) and (times.min() < -EPS_S or times.max() > self.duration_s + EPS_S):
                raise ValueError(f"{name}: a time outside the path [0, {self.duration_s}] s")

    def point_at(self, t_s: float, points: np.ndarray | None = None) -> np.ndarray:
        """The point at ``t_s`` [s] (3,) of ``points_m`` (or of ``points``, one per sample):
        linear between samples, clamped to the ends."""
        points = self.points_m if points is None else points
        u = min(max(t_s / self.period_s, 0.0), len(points) - 1.0)
        k = min(int(u), len(points) - 2)
        f = u - k
        return points[k] + f * (points[k + 1] - points[k])

    def phi_at(self, t_s: float) -> float | None:
        """The wrist angle at ``t_s`` [s], linear between samples; None where the path
        leaves the wrist alone (NaN samples) or has no wrist angles."""
        if self.phi_rad is None:
            return None
        u = min(max(t_s / self.period_s, 0.0), len(self.points_m) - 1.0)
        k = min(int(u), len(self.points_m) - 2)
        a, b = float(self.phi_rad[k]), float(self.phi_rad[k + 1])
        if not math.isfinite(a):
            return None
        return a + (u - k) * (b - a) if math.isfinite(b) else a

    def sample_at(self, t_s: float) -> int:
        """The index of the sample nearest ``t_s`` [s]."""
        return int(min(max(round(t_s / self.period_s), 0), len(self.points_m) - 1))

    def speed_near(self, t_s: float) -> float:
        """The path's largest speed [m/s] over the sample intervals within one period of
        ``t_s`` [s] (the wrist's turn counts at 0.1 m per rad)."""
        points, n = np.asarray(self.points_m), len(self.points_m)
        k = min(max(int(t_s / self.period_s), 0), n - 2)
        lo, hi = max(k - 1, 0), min(k + 2, n - 1)
        steps = np.linalg.norm(np.diff(points[lo : hi + 1], axis=0), axis=1)
        if self.phi_rad is not None:
            turns = np.abs(np.diff(np.nan_to_num(np.asarray(self.phi_rad)[lo : hi + 1])))
            steps = np.maximum(steps, 0.1 * turns)
        return float(steps.max()) / self.period_s

    def peak_speed(self) -> float:
        """The path's largest speed between samples [m/s]."""
        steps = np.linalg.norm(np.diff(np.asarray(self.points_m), axis=0), axis=1)
        return float(steps.max()) / self.period_s


class Playback:
    """The time base of a path: its time runs at rate ``rate`` (k), which moves towards
    the feed override (0 while paused) by at most ``slew_per_s`` [1/s] each second, and
    stops exactly at a stop: a single step's line end, an M0, an M1 with the optional
    stop on (where the planned path is at rest, it stops there at once; elsewhere it
    brakes in time: a rate k needs k^2 / (2 slew) of path time to stand).

    ``duration_s`` [s]; ``spans`` (m, 3) [line, start, end] and ``pauses`` (p, 3) [time,
    line, optional] in path time as :class:`SampledPath` has them (None: none);
    ``rest_at(t)``: the planned path is at rest at path time t; ``approach_s``: where a
    program's own path starts [s]. Its commands (:meth:`steer`) and :meth:`advance` run
    in the control thread; other threads read :meth:`state` (one frozen record)."""

    def __init__(
        self,
        duration_s: float,
        slew_per_s: float,
        rest_at: Callable[[float], bool],
        spans: np.ndarray | None = None,
        pauses: np.ndarray | None = None,
        approach_s: float = 0.0,
    ) -> None:
        self.duration_s, self.slew, self.rest_at = duration_s, slew_per_s, rest_at
        self.spans = None if spans is None else np.asarray(spans, dtype=float).reshape(-1, 3)
        table = np.zeros((0, 3)) if pauses is None else np.asarray(pauses, dtype=float)
        self.pauses = table.reshape(-1, 3)[np.argsort(table.reshape(-1, 3)[:, 0], kind="stable")]
        self.approach_s = approach_s
        self.rate = 1.0
        self.override = 1.0
        self.optional_stop = False
        self._pausing = False  # the operator's pause (or a stop reached): target rate 0
        self._held: str | None = None  # why it stands at a stop, in words
        self._step: tuple[float, int | None] | None = None  # a single step's stop
        self._stop_line: int | None = None
        self._t_s = 0.0
        self.state = self._state()

    @classmethod
    def of(cls, path: SampledPath) -> Playback:
        """The playback of a sampled path: its slew from its peak speed, rest where the
        samples within a period move less than one tick at EXTRA_ACCEL_M_S2 allows."""
        slew = min(MAX_SLEW_PER_S, EXTRA_ACCEL_M_S2 / max(path.peak_speed(), 1e-6))
        rest_speed = EXTRA_ACCEL_M_S2 * path.period_s  # stopped in one tick: <= the bound

        def rest_at(t_s: float) -> bool:
            return path.speed_near(t_s) <= rest_speed

        return cls(path.duration_s, slew, rest_at, path.spans, path.pauses, path.approach_s)

    # ---- commands (the control thread) ----
    def steer(
        self, action: str, override: float | None = None, on: bool | None = None
    ) -> FeedState:
        """``action``: "pause" (brake along the path and stand), "resume" (back to the
        override), "step" (run to the end of the program line, stop there exactly),
        "feed" (set ``override``, 0.1 to 1.0) or "optional_stop" (``on``: M1 stops).
        The state after it. ValueError naming the field; MotionRefused for a step on a
        path with no program lines."""
        if action == "pause":
            if self._held is None:  # standing at a stop already: it stays that stop's
                self._stop_line = None
            self._pausing, self._step = True, None
        elif action == "resume":
            self._pausing, self._held, self._step, self._stop_line = False, None, None, None
        elif action == "step":
            self._start_step()
        elif action == "feed":
            self.override = feed_override(override)
        elif action == "optional_stop":
            if not isinstance(on, bool):
                raise ValueError(f"on: expected true or false, got {on!r:.40}")
            self.optional_stop = on
        else:
            raise ValueError(
                f"action: expected pause, resume, step, feed or optional_stop, got {action!r:.40}"
            )
        self.state = self._state()
        return self.state

    def _start_step(self) -> None:
        if self.spans is None or not len(self.spans):
            raise MotionRefused("step: this run is not a program: it has no lines to step by")
        t, k = self._t_s, self.rate
        ends = sorted({(float(e), int(line)) for line, _s, e in self.spans if e > t + EPS_S})
        if t < self.approach_s - EPS_S:  # the approach: step to the program's start
            ends.insert(0, (self.approach_s, None))
        braking = k * k / (2.0 * self.slew) if self.slew > 0 else math.inf
        for end, line in ends:  # the first line end it can stop at exactly
            if self.rest_at(end) or end - t >= braking:
                self._step = (end, line)
                self._pausing, self._held, self._stop_line = False, None, line
                return
        raise MotionRefused("step: the program ends before the next line's end")

    # ---- the tick ----
    def _next_stop(self, t: float) -> tuple[float, str, int | None] | None:
        stops: list[tuple[float, str, int | None]] = []
        if self._step is not None:
            end, line = self._step
            where = "the program's start" if line is None else f"the end of line {line}"
            stops.append((end, f"single step: stopped at {where}", line))
        for when, line, optional in self.pauses:
            if when > t + EPS_S and (not optional or self.optional_stop):
                code = "M1 (optional stop)" if optional else "M0"
                stops.append((float(when), f"{code} at line {int(line)}: press Resume", int(line)))
                break
        return min(stops, key=lambda s: s[0]) if stops else None

    def advance(self, t_s: float, dt_s: float) -> float:
        """The path time [s] one tick of ``dt_s`` [s] after ``t_s``, with the rate moved
        towards its target and stopped exactly at the next stop."""
        target = 0.0 if self._pausing else self.override
        k, step = self.rate, self.slew * dt_s
        k = min(target, k + step) if target >= k else max(target, k - step)
        stop = self._next_stop(t_s)
        t_next = t_s + k * dt_s
        if stop is not None:
            t_stop, why, line = stop
            if not self.rest_at(t_stop):  # brake in time: k <= sqrt(2 slew (t_stop - t))
                k = min(k, math.sqrt(2.0 * self.slew * max(t_stop - t_s, 0.0)))
                t_next = t_s + k * dt_s
            if t_next >= t_stop - EPS_S:
                t_next, k = t_stop, 0.0
                self._pausing, self._held, self._step, self._stop_line = True, why, None, line
        if self._pausing and k == 0.0 and self._held is None:
            self._held = "paused"
        self.rate, self._t_s = k, t_next
        self.state = self._state()
        return t_next

    def _state(self) -> FeedState:
        if self._held is not None:
            paused: str | None = self._held
        else:
            paused = "pausing" if self._pausing else None
        left = max(self.duration_s - self._t_s, 0.0) / max(self.override, FEED_MIN)
        return FeedState(
            rate=self.rate,
            override=self.override,
            paused=paused,
            time_left_s=left,
            optional_stop=self.optional_stop,
            stop_line=self._stop_line,
        )


def feed_override(value: Any) -> float:
    """A feed override in [FEED_MIN, FEED_MAX] (1.0 = 100 %); ValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(
            f"override: expected a number from {FEED_MIN} to {FEED_MAX}, got {value!r:.40}"
        )
    if not FEED_MIN - 1e-12 <= value <= FEED_MAX + 1e-12:
        raise ValueError(
            f"override: {value * 100:.0f} % is outside {FEED_MIN * 100:.0f} to "
            f"{FEED_MAX * 100:.0f} % (the program was checked at 100 % feed: never above)"
        )
    return min(max(float(value), FEED_MIN), FEED_MAX)


class PathSource:
    """Plays a :class:`SampledPath` as the loop's goal source (the node's side of a run).

    ``source_id`` names it on the link (the station follows its run by it); ``t_s`` is its
    time and ``program_line`` the line it executes (None: none); ``playback`` its time
    base (feed override, pause, step, M0/M1: :class:`Playback`). At 100 % feed and no
    stop its setpoints are what app/runs/source.py ``TrajectorySource`` gives on the
    planned path at the samples; at rate k the path's time advances k dt a tick and the
    lead (feed-forward) is k lead_s, so a standing path commands its goal."""

    def __init__(self, path: SampledPath, source_id: str) -> None:
        self.path, self.source_id, self.name = path, source_id, path.name
        self.t_s = 0.0
        self.finished = False
        self.program_line: int | None = None
        self.playback = Playback.of(path)

    @property
    def feed_state(self) -> FeedState:
        return self.playback.state

    def progress(self) -> Progress:
        path = self.path
        stop_s = path.duration_s - path.approach_s - path.timed_s
        phase = path.phases[int(path.phase_index[path.sample_at(self.t_s)])]
        return Progress.at(phase, self.t_s, path.approach_s, path.timed_s, stop_s)

    def next(self, dt_s: float) -> Setpoint:
        self.t_s = self.playback.advance(self.t_s, dt_s)
        path, k = self.path, self.playback.rate
        i = path.sample_at(self.t_s)
        goal = path.point_at(self.t_s)
        lead = k * path.lead_s
        if path.commanded_m is not None and k == 1.0:  # the point ahead, as planned
            commanded = path.point_at(self.t_s, path.commanded_m)
        else:
            commanded = path.point_at(self.t_s + lead) if lead else goal
        self.finished = self.t_s >= path.duration_s - 1e-9
        phase = path.phases[int(path.phase_index[i])]
        if path.lines is not None:
            line = int(path.lines[i])
            if path.spans is not None and len(path.spans) and line >= 0:  # exact between samples
                spans = path.spans
                j = int(np.searchsorted(spans[:, 1], self.t_s, side="right")) - 1
                line = int(spans[min(max(j, 0), len(spans) - 1), 0])
            self.program_line = line if line >= 0 and phase == "timed" else None
            stopped_at = self.playback.state.stop_line
            if k == 0.0 and stopped_at is not None:  # standing at a stop: its line
                self.program_line = stopped_at
        phi = None if path.phi_rad is None else path.phi_at(self.t_s + lead)
        return Setpoint(
            point_m=commanded, goal_m=goal, phi_rad=phi, phase=phase, finished=self.finished
        )

"""A checked timed path as data, and the goal source that plays it on the robot node.

The station plans and checks a run (a sinusoid, a chirp, a G-code program: app/runs/,
app/programs/) and sends the robot node its samples, one per loop period, not code: the
node plays them (:class:`PathSource`) and still gates every setpoint. Between samples
(a late tick) a point is interpolated linearly; at a sample it is the planned point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.control.sources import Progress, Setpoint

MAX_SAMPLES = 2_000_000  # a bound on what a node takes (runs.max_samples is far below)


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


class PathSource:
    """Plays a :class:`SampledPath` as the loop's goal source (the node's side of a run).

    ``source_id`` names it on the link (the station follows its run by it); ``t_s`` is its
    time and ``program_line`` the line it executes (None: none). Its setpoints are what
    app/runs/source.py ``TrajectorySource`` gives on the planned path at the samples."""

    def __init__(self, path: SampledPath, source_id: str) -> None:
        self.path, self.source_id, self.name = path, source_id, path.name
        self.t_s = 0.0
        self.finished = False
        self.program_line: int | None = None

    def progress(self) -> Progress:
        path = self.path
        stop_s = path.duration_s - path.approach_s - path.timed_s
        phase = path.phases[int(path.phase_index[path.sample_at(self.t_s)])]
        return Progress.at(phase, self.t_s, path.approach_s, path.timed_s, stop_s)

    def next(self, dt_s: float) -> Setpoint:
        self.t_s += dt_s
        path = self.path
        k = path.sample_at(self.t_s)
        goal = path.point_at(self.t_s)
        if path.commanded_m is not None:  # the point ahead, as planned (exact at a sample)
            commanded = path.point_at(self.t_s, path.commanded_m)
        else:
            commanded = path.point_at(self.t_s + path.lead_s) if path.lead_s else goal
        self.finished = self.t_s >= path.duration_s - 1e-9
        phase = path.phases[int(path.phase_index[k])]
        if path.lines is not None:
            line = int(path.lines[k])
            self.program_line = line if line >= 0 and phase == "timed" else None
        phi = None if path.phi_rad is None else path.phi_at(self.t_s + path.lead_s)
        return Setpoint(
            point_m=commanded, goal_m=goal, phi_rad=phi, phase=phase, finished=self.finished
        )

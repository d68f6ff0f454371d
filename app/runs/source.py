"""A planned run as the control loop's goal source (mode "test")."""

from __future__ import annotations

import numpy as np

from app.control.sources import Progress, Setpoint
from app.control.state import FeedState
from app.link.paths import EXTRA_ACCEL_M_S2, MAX_SLEW_PER_S, Playback, SampledPath
from app.runs.trajectories import PlannedRun

REST_PROBE_S = 0.005  # a planned path is at rest where it moves less than EXTRA_ACCEL * this


def program_marks(plan: PlannedRun) -> tuple[np.ndarray | None, np.ndarray | None]:
    """A program's segments as (m, 3) [line, start, end] and its M0 / M1 as (p, 3) [time,
    line, optional] in run time [s] (the approach first); (None, None) for a run that is
    not a program (its path has no ``segments``)."""
    params = plan.params
    segments = getattr(params, "segments", None)
    if segments is None:
        return None, None
    offset = plan.approach_s
    starts, ends = params.start_s + offset, params.end_s + offset
    spans = np.array(
        [[s.line, a, b] for s, a, b in zip(segments, starts, ends, strict=True)], dtype=float
    ).reshape(-1, 3)
    pauses = np.array(
        [
            [a, s.line, 1.0 if s.optional else 0.0]
            for s, a in zip(segments, starts, strict=True)
            if s.kind == "pause"
        ],
        dtype=float,
    ).reshape(-1, 3)
    return spans, pauses


class TrajectorySource:
    """Plays a PlannedRun; with ``lead_s`` > 0 commands the point that far ahead (feed-forward
    for the servos' position lag) while reporting the nominal point as the goal.

    Its time base is a :class:`~app.link.paths.Playback` (feed override, pause, single
    step, M0 / M1), as the robot node's ``PathSource`` has it; ``feed_state`` says where
    it stands (over the link, the station's copy is the node's, from its snapshots), and
    ``start_play`` the override and optional stop it starts with."""

    name = "test"

    def __init__(self, plan: PlannedRun, lead_s: float = 0.0) -> None:
        self.plan = plan
        self.lead_s = lead_s
        self.t_s = 0.0
        self.finished = False
        # a G-code program's path (app/programs ProgramPath) says its line at each time
        self._line_at = getattr(plan.params, "line_at", None)
        self._lines_between = getattr(plan.params, "lines_between", None)
        self.program_line: int | None = None  # the line being executed (None: not a program)
        # every line the timed part has met, in order, including one crossed whole between
        # two ticks (a tick late by more than the line lasts), which no sample shows
        self.lines_met: list[int] = []
        self._timed_s: float | None = None  # the timed part's time at the last tick
        # the feed override and optional stop it starts with (a program path says them)
        self.start_play: dict[str, object] = {
            "override": float(getattr(plan.params, "feed_override", 1.0)),
            "optional_stop": bool(getattr(plan.params, "optional_stop", False)),
        }
        self._playback: Playback | None = None
        self.feed_state: FeedState | None = None

    @property
    def playback(self) -> Playback:
        """This run's time base, made at its first use (in the loop: its first tick)."""
        if self._playback is None:
            plan = self.plan
            peak = max(float(plan.params.peaks()[0]), 0.1)  # the approach's speed too
            slew = min(MAX_SLEW_PER_S, EXTRA_ACCEL_M_S2 / peak)
            rest_speed = EXTRA_ACCEL_M_S2 * REST_PROBE_S

            def rest_at(t_s: float) -> bool:
                h = REST_PROBE_S
                a, b = plan.point_at(t_s - h), plan.point_at(t_s + h)
                return float(np.linalg.norm(b - a)) / (2 * h) <= rest_speed

            spans, pauses = program_marks(plan)
            playback = Playback(plan.duration_s, slew, rest_at, spans, pauses, plan.approach_s)
            if "override" in self.start_play:
                playback.steer("feed", override=self.start_play["override"])  # type: ignore[arg-type]
            if "optional_stop" in self.start_play:
                playback.steer("optional_stop", on=self.start_play["optional_stop"])  # type: ignore[arg-type]
            self._playback = playback
        return self._playback

    def sampled(self, period_s: float) -> SampledPath:
        """This run as data for a robot node (app/link/paths.py): its points, wrist angles,
        phases and program lines at every ``period_s`` [s], what :meth:`next` gives there."""
        plan = self.plan
        times, points = plan.sample(period_s)
        if times[-1] < plan.duration_s:  # rounding: one more sample, at or past the end
            times = np.append(times, times[-1] + period_s)
            points = np.vstack([points, plan.point_at(plan.duration_s)])
        times = np.arange(len(times)) * period_s  # sample k at k periods, exactly
        phases = ("approach", "timed", "stop")
        index = np.array([phases.index(plan.phase_at(float(t))) for t in times])
        phi = None
        if plan.moves_wrist:
            phi = np.array([plan.phi_at(float(t)) for t in times], dtype=float)
        commanded = None
        if self.lead_s:  # the feed-forward point, as next() commands it
            commanded = np.array([plan.point_at(float(t) + self.lead_s) for t in times])
        lines = None
        if self._line_at is not None:
            timed = np.clip(times - plan.approach_s, 0.0, plan.params.duration_s)
            lines = np.where(index == 1, self._line_at(timed), -1).astype(int)
        spans, pauses = program_marks(plan)
        return SampledPath(
            period_s=period_s,
            duration_s=plan.duration_s,
            points_m=points,
            phases=phases,
            phase_index=index,
            phi_rad=phi,
            lines=lines,
            commanded_m=commanded,
            lead_s=self.lead_s,
            approach_s=plan.approach_s,
            timed_s=plan.params.duration_s,
            name=self.name,
            spans=spans,
            pauses=pauses,
        )

    def progress(self) -> Progress:
        t, plan = self.t_s, self.plan  # t_s is one float: safe to read from another thread
        test_s = plan.params.duration_s
        stop_s = plan.duration_s - plan.approach_s - test_s
        return Progress.at(plan.phase_at(t), t, plan.approach_s, test_s, stop_s)

    def next(self, dt_s: float) -> Setpoint:
        playback = self.playback
        self.t_s = playback.advance(self.t_s, dt_s)
        self.feed_state = playback.state
        lead = playback.rate * self.lead_s  # a standing path commands its goal
        goal = self.plan.point_at(self.t_s)
        commanded = self.plan.point_at(self.t_s + lead) if lead else goal
        self.finished = self.t_s >= self.plan.duration_s
        phase = self.plan.phase_at(self.t_s)
        if self._line_at is not None:  # only in the timed part: the approach and the
            # stop (both of zero length for a program that starts where the robot is) are not
            # the program's
            timed = min(max(self.t_s - self.plan.approach_s, 0.0), self.plan.params.duration_s)
            self.program_line = int(self._line_at(timed)) if phase == "timed" else None
            stopped_at = self.feed_state.stop_line
            if playback.rate == 0.0 and stopped_at is not None:  # standing at a stop
                self.program_line = stopped_at
            if phase == "timed" and self._lines_between is not None:
                since = 0.0 if self._timed_s is None else self._timed_s  # from its start
                for line in self._lines_between(since, timed):
                    if not self.lines_met or self.lines_met[-1] != line:
                        self.lines_met.append(line)
                self._timed_s = timed
        # with a wrist the path's phi, at the commanded point's time (None: left alone)
        phi = self.plan.phi_at(self.t_s + lead)
        return Setpoint(
            point_m=commanded,
            goal_m=goal,
            phi_rad=phi,
            phase=phase,
            finished=self.finished,
        )

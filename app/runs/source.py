"""A planned run as the control loop's goal source (mode "test")."""

from __future__ import annotations

from app.control.sources import Progress, Setpoint
from app.runs.trajectories import PlannedRun


class TrajectorySource:
    """Plays a PlannedRun; with ``lead_s`` > 0 commands the point that far ahead (feed-forward
    for the servos' position lag) while reporting the nominal point as the goal."""

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

    def progress(self) -> Progress:
        t, plan = self.t_s, self.plan  # t_s is one float: safe to read from another thread
        test_s = plan.params.duration_s
        stop_s = plan.duration_s - plan.approach_s - test_s
        return Progress.at(plan.phase_at(t), t, plan.approach_s, test_s, stop_s)

    def next(self, dt_s: float) -> Setpoint:
        self.t_s += dt_s
        goal = self.plan.point_at(self.t_s)
        commanded = self.plan.point_at(self.t_s + self.lead_s) if self.lead_s else goal
        self.finished = self.t_s >= self.plan.duration_s
        phase = self.plan.phase_at(self.t_s)
        if self._line_at is not None:  # only in the timed part: the approach and the
            # stop (both of zero length for a program that starts where the robot is) are not
            # the program's
            timed = min(max(self.t_s - self.plan.approach_s, 0.0), self.plan.params.duration_s)
            self.program_line = int(self._line_at(timed)) if phase == "timed" else None
            if phase == "timed" and self._lines_between is not None:
                since = 0.0 if self._timed_s is None else self._timed_s  # from its start
                for line in self._lines_between(since, timed):
                    if not self.lines_met or self.lines_met[-1] != line:
                        self.lines_met.append(line)
                self._timed_s = timed
        # with a wrist the path's phi, at the commanded point's time (None: left alone)
        phi = self.plan.phi_at(self.t_s + self.lead_s)
        return Setpoint(
            point_m=commanded,
            goal_m=goal,
            phi_rad=phi,
            phase=phase,
            finished=self.finished,
        )

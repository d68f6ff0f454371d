"""Runs: start a planned test, record it, abort it, find it again after a restart.

A run's record is saved when it starts and as it goes (app/runs/run.py); a run that a
crash left ``running`` is finished as ``interrupted`` from its logs when the manager next
loads the folder (app/runs/recovery.py).
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
import uuid
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.control.errors import GoalRejected, MotionRefused
from app.control.model import RobotModel
from app.control.sources import Progressing
from app.runs.feasibility import check_path
from app.runs.logs import RunLog
from app.runs.recorder import Recorder, wait_for_recorders
from app.runs.recovery import abandoned, draw_report, recover
from app.runs.run import Run
from app.runs.source import TrajectorySource
from app.runs.trajectories import SinusoidParams, TimedPath, plan_sinusoid

if TYPE_CHECKING:
    from app.control.controller import Controller

log = logging.getLogger(__name__)
START_TIMEOUT_S = 2.0


@dataclass(frozen=True)
class PreparedRun:
    """A planned and checked run, not started yet (see RunManager.prepare)."""

    kind: str
    params: dict[str, Any]
    lead_s: float
    source: TrajectorySource
    start_m: np.ndarray
    model: RobotModel | None = None  # what it was checked against (refused under another)


class RunManager:
    """Owns the runs of one controller; one run at a time."""

    def __init__(self, controller: Controller, folder: Path) -> None:
        self.controller = controller
        self.folder = folder
        self._runs: dict[str, Run] = {}
        self._active: tuple[Run, TrajectorySource] | None = None
        self._lock = threading.Lock()
        # one mover at a time: a procedure asks the controller's owner whether it may
        # start, and the owner asks this manager whether a run is in progress
        controller.owner.add_mover(self.busy)
        self._load_saved()

    def _load_saved(self) -> None:
        """Every saved run; one that a crash left running is finished as interrupted."""
        for path in sorted(self.folder.glob("*/run.json")):
            try:
                run = Run.load(path)
            except (OSError, ValueError, TypeError) as exc:
                log.warning("%s: not a run record, left out: %s", path, exc)
                continue
            if abandoned(run):
                self._recover(run)
            run.done.set()
            self._runs[run.run_id] = run

    def _recover(self, run: Run) -> None:
        rate_hz = run.conditions.get("loop_rate_hz")
        period_s = 1.0 / rate_hz if rate_hz else self.controller.period_s
        skip_s = self.controller.settings.runs.stats_skip_s
        rows: list[dict[str, Any]] = []
        try:
            rows = recover(run, skip_s, period_s)
        except OSError as exc:  # listed as interrupted all the same
            log.warning("run %s: could not save its record: %s", run.run_id, exc)
        log.warning("run %s was interrupted: %s", run.run_id, run.reason)
        if rows:  # the report after start-up: the server answers meanwhile
            threading.Thread(
                target=draw_report,
                args=(run, rows, skip_s, period_s),
                name=f"report-{run.run_id}",
                daemon=True,
            ).start()

    def list(self) -> list[Run]:
        return sorted(self._runs.values(), key=lambda r: r.started_at, reverse=True)

    def get(self, run_id: str) -> Run | None:
        return self._runs.get(run_id)

    def plan(self, params: TimedPath, model: RobotModel | None = None):
        """(plan, start point) from where the robot is, checked against ``model`` (None: the
        controller's model in use); GoalRejected if infeasible."""
        model = model or self.controller.model
        snap = self.controller.snapshot()
        # where the loop starts a new path (commands.start_point): the command while it
        # holds it; after torque on, a stop or a fault, where the arm is measured (resync);
        # the launch checks the robot is still within runs' tolerance of this point
        holding = snap.torque and not snap.estopped and not snap.faults
        start = snap.start_m if holding else snap.point_measured_m
        if not np.isfinite(start).all():
            start = snap.point_measured_m
        if not np.isfinite(start).all():
            raise MotionRefused("the robot's position is unknown: check the bus")
        try:
            plan = plan_sinusoid(params, start)
        except ValueError as exc:
            raise GoalRejected(str(exc)) from exc
        period_s, limit = self.controller.period_s, self.controller.settings.runs.max_samples
        if not math.isfinite(plan.duration_s) or plan.samples(period_s) > limit:
            # bounds the time the check takes
            raise GoalRejected(
                f"duration_s: the run with its approach and stop would last "
                f"{plan.duration_s:.1f} s, over the limit of {limit * period_s:.0f} s "
                f"(runs.max_samples = {limit} loop periods)"
            )
        times, points = plan.sample(period_s)
        phi = self._check_wrist(plan, times)
        check_path(model.gate, times, points, snap.joints_measured_rad, phi)
        return plan, start

    def _check_wrist(self, plan, times: np.ndarray) -> np.ndarray | None:
        """A path that turns the wrist: its phi (N,) [rad] at ``times`` (N,) [s], checked
        against the wrist (there is one, within its limits and speed); GoalRejected naming
        the path's phi field. None for a path that leaves the wrist alone."""
        if not plan.moves_wrist:
            return None
        params, gate = plan.params, self.controller.gate
        field = params.phi_field
        if gate.wrist_min_rad is None or gate.wrist_max_rad is None:
            raise GoalRejected(
                f"{field}: no wrist axis is configured ([wrist] enabled = false), so the "
                "tool cannot turn"
            )
        phi = np.array([plan.phi_at(float(t)) for t in times])
        worst = float(phi[np.argmax(np.abs(phi))])
        if phi.min() < gate.wrist_min_rad or phi.max() > gate.wrist_max_rad:
            raise GoalRejected(
                f"{field}: phi reaches {math.degrees(worst):.1f} deg, outside the wrist's "
                f"limits [{math.degrees(gate.wrist_min_rad):.1f}, "
                f"{math.degrees(gate.wrist_max_rad):.1f}] deg"
            )
        speed = params.phi_peak_speed()
        limit = self.controller.settings.wrist.max_speed_rad_s
        if speed > limit:
            raise GoalRejected(
                f"{field}: the wrist would turn at {speed:.2f} rad/s, over its limit "
                f"{limit:.2f} rad/s (wrist.max_speed_rad_s)"
            )
        return phi

    def start_sinusoid(self, params: SinusoidParams) -> Run:
        """Plan, check, start and record a sinusoid run; raises before anything moves."""
        return self.start(params, "sinusoid")

    def start(self, params: TimedPath, kind: str, record: dict[str, Any] | None = None) -> Run:
        """Plan, check, start and record a run of any timed path; raises before any motion."""
        return self.launch(self.prepare(params, kind, record))

    def prepare(
        self,
        params: TimedPath,
        kind: str,
        record: dict[str, Any] | None = None,
        model: RobotModel | None = None,
    ) -> PreparedRun:
        """Plan and check a run from where the robot is now; nothing moves. The slow half of
        :meth:`start`, so a caller can decide, after it, whether the run is still wanted.
        ``record``: the parameters saved in run.json (default: the path's own fields, for
        the dataclass paths; a G-code program saves its text instead). ``model``: the
        robot model the run was checked against (a program's check, in a worker; None:
        the one in use now); the run is refused if another is in use when it starts."""
        self._refuse_if_busy()
        model = model or self.controller.model
        plan, start = self.plan(params, model)
        lead = self.controller.settings.runs.feedforward_lead_s if params.feedforward else 0.0
        saved = asdict(params) if record is None else record  # type: ignore[call-overload]
        return PreparedRun(kind, saved, lead, TrajectorySource(plan, lead), start, model)

    def launch(self, prepared: PreparedRun) -> Run:
        """Start and record a prepared run. The loop refuses it if the robot has left the
        planned start point meanwhile (the plan would step), or another run started."""
        with self._lock:
            self._refuse_if_busy()
            p = prepared
            return self._launch(p.kind, p.params, p.lead_s, p.source, p.start_m, p.model)

    def start_source(
        self, kind: str, params: dict[str, Any], source: Any, model: RobotModel | None = None
    ) -> Run:
        """Record a run of a ready-made source that starts smoothly from wherever the robot
        is (e.g. hold-in-world, which blends in), so no start point is checked; refused if
        ``model`` (what the source was built on; None: not checked) is no longer in use."""
        with self._lock:
            self._refuse_if_busy()
            return self._launch(kind, params, 0.0, source, None, model)

    def busy(self) -> str | None:
        """Why another mover may not start now (a run in progress), or None. The
        controller's ``MotionOwner`` asks it (``add_mover``): procedures ask the owner."""
        active = self._active
        if active is not None and active[0].state == "running":
            return f"run {active[0].run_id} is in progress; abort it first"
        return None

    def _refuse_if_busy(self) -> None:
        # a procedure (calibration, tuning) holds the robot: only its own thread may start
        # runs (app/control/owner.py); the controller checks again when the run starts
        self.controller.owner.check()
        if (why := self.busy()) is not None:
            raise MotionRefused(why)

    def _launch(
        self,
        kind: str,
        params: dict[str, Any],
        lead: float,
        source: Any,
        start: np.ndarray | None,
        model: RobotModel | None = None,
    ) -> Run:
        run = self._new_run(kind, params, lead)
        metadata = {
            "run_id": run.run_id,
            "params": json.dumps(run.params),
            "started_at_utc": run.started_at_utc,
        }
        run_log = RunLog(
            run.folder, metadata, on_flush=run.progress, settings=self.controller.settings
        )
        skip = self.controller.settings.runs.stats_skip_s
        recorder = Recorder(run, self.controller, source, run_log, skip)
        self.controller.add_listener(recorder.on_tick)
        try:
            run.write()  # the record exists from the start: a crash leaves it "running"
            tolerance = math.inf if start is None else 0.002
            expected = np.zeros(3) if start is None else start
            started = self.controller.run_source(source, expected, tolerance, model)
            started.result(timeout=START_TIMEOUT_S)
        except BaseException:
            self.controller.remove_listener(recorder.on_tick)
            recorder.discard()
            raise
        self._runs[run.run_id] = run
        self._active = (run, source)
        return run

    def abort(self, run_id: str, reason: str = "aborted by the operator") -> Run:
        run = self._runs[run_id]
        if self._active is not None and self._active[0] is run and run.state == "running":
            run.abort_reason = reason
            self.controller.stop_source(self._active[1]).result(timeout=START_TIMEOUT_S)
        return run

    def steer(self, action: str, kinds: tuple[str, ...] = ("program",), **values: Any) -> Any:
        """Steer the running run's time (app/link/paths.py ``Playback.steer``): "pause",
        "resume", "step", "feed" (``override`` 0.1 to 1.0) or "optional_stop" (``on``).
        Returns (run, its FeedState) once the loop took it. MotionRefused when no run of
        ``kinds`` is running (or a step on a path with no lines); ValueError naming the
        field (``override``, ``on``); nothing moves on a refusal."""
        active = self._active
        if active is None or active[0].state != "running" or active[0].kind not in kinds:
            raise MotionRefused(f"no {' or '.join(kinds)} is running: nothing to {action}")
        run, source = active
        if action in ("resume", "step"):
            self.controller.owner.check()  # a procedure holds the robot: it may not move
        steer_source = getattr(self.controller, "steer_source", None)
        if steer_source is not None:  # over the link: the node plays it
            future = steer_source(source, action, **values)
        else:  # a loop in this process plays the station's source itself
            playback = source.playback
            future = self.controller.submit(lambda: playback.steer(action, **values))
        state = future.result(
            timeout=max(START_TIMEOUT_S, self.controller.settings.server.command_timeout_s)
        )
        return run, state

    def progress(self, run_id: str) -> dict[str, Any] | None:
        """How far the running run ``run_id`` is (see app/control/sources.py's ``Progress``;
        a length not known yet is None), or None when it is not the one running."""
        active = self._active
        if active is None or active[0].run_id != run_id or active[0].state != "running":
            return None
        source = active[1]
        if not isinstance(source, Progressing):
            return None
        values = asdict(source.progress())
        out = {
            k: v if not isinstance(v, float) or math.isfinite(v) else None
            for k, v in values.items()
        }
        line = getattr(source, "program_line", None)  # a G-code program's line in execution
        if line is not None:
            out["program_line"] = line
        feed = getattr(source, "feed_state", None)  # a path's feed override, pause, time left
        if feed is not None:
            out["feed_override"] = feed.override
            out["feed_rate"] = feed.rate
            out["paused"] = feed.paused
            out["time_left_s"] = feed.time_left_s
            out["optional_stop"] = feed.optional_stop
            out["stop_line"] = feed.stop_line
        return out

    def close(self) -> None:
        """At shutdown: stop the active run (its log is finalised) and drop the plan."""
        if self._active is not None:
            run, _ = self._active
            if run.state == "running":
                self.abort(run.run_id, "server shutting down")
                run.done.wait(timeout=5.0)
            self._active = None
        wait_for_recorders()  # reports still being drawn: native code must not be cut off

    def _new_run(self, kind: str, params: dict[str, Any], lead_s: float) -> Run:
        run_id = time.strftime("%Y%m%d-%H%M%S") + "-" + uuid.uuid4().hex[:4]
        settings = self.controller.settings
        conditions = {
            "robot": settings.robot.model_dump(),
            # the model the loop used (a geometry calibration's legs, once applied)
            "robot_model": self.controller.model.describe(),
            "backend": self.controller.backend,
            "loop_rate_hz": settings.loop.rate_hz,
            "feedforward_lead_s": lead_s,
            "joints": [j.model_dump() for j in settings.hardware.joints],
            # the position gains the servos used (register units), per leg servo id
            "gains": {str(k): asdict(g) for k, g in self.controller.gains.items()},
        }
        return Run(run_id, kind, params, conditions, self.folder / run_id)

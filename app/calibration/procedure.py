"""The guided calibration on the robot: plan, move, rest, measure, fit, validate, apply.

A ``CalibrationRun`` plans its poses (``fit.plan``: D-optimal fit poses, random held-out
ones; the observability is known before anything moves), then, in its own thread, moves
the arm to each pose with the controller's joint-space move, waits for it to come to rest
(``REST_TICKS`` fresh ticks within ``REST_TOLERANCE_RAD``, every joint slower than
``REST_SPEED_RAD_S``; a stalled simulator's repeated state is not rest), and averages the
joints and the external measurement over ``AVERAGE_TICKS`` fresh ticks (a tick without
a fresh measurement is skipped; none for ``MEASURE_WAIT_S`` fails the run, as readings
spread beyond ``SPREAD_LIMIT_M`` do; a failed run keeps the pairs it measured). Then it
fits (``fit.fit``) and writes its files under the runs folder: ``pairs.csv`` (what it
measured: ``deltadash calibrate --from-csv`` fits it again offline), ``report.png`` (the
residuals before and after) and ``result.json``.

The measurement is pluggable: ``measure(snapshot)`` returns the platform in the
measurement frame [m] (3,), NaN when there is none. A run's ``measurement`` chooses it:
``"external"`` (the default), the snapshot's ``external_m`` (the twin's own motion
capture; a real bus has none); ``"pose-input"``, the latest fresh pose of a motion-capture
marker on the platform streamed through the pose input (``"body": "platform"`` on
POST/WebSocket /api/mav/pose or the UDP JSON input; ``pose_input``). The measurement
frame is the motion-capture system's world frame (fitted, 6-DoF); the base must stay still
in it during the run. The marker need not be at the platform's centre: without a wrist the
platform only translates, so a constant marker offset is part of the fitted frame's
translation.

A probe run (``source="probe"``, app/calibration/probe.py) instead touches a flat plate at
``plate_z_m`` at points spread over it and fits what z-only heights can observe. Its
``probe`` mode says where the touches come from. "touch": the arm really touches the
plate, a probe without a probe switch: for each point the tool tip moves to
``TOUCH_CLEARANCE_M`` above the plate's stated height, the controller's touch
(app/control/touch.py) goes straight down (direction (0, 0, -1), the run's speed and set
force or the ``[contact]`` defaults, ``TOUCH_BEYOND_M`` past the stated height at most)
until the force estimate says contact, and back up; the legs' joints as read at the tick
contact was seen (``TouchResult.joints_at_contact_rad``) are the touch. A touch that ends
otherwise (no plate there, a fault) fails the run naming the point. Here ``plate_z_m`` is
the height of the tool tip ([tool] offset_m) at contact; the fit's platform height is
``plate_z_m`` less the tip's z offset. "model": computed from the twin's true model
(``probe(xy, plate_z, seed)``, ``probe.twin_probe``; the arm is not moved). By default a
run touches where the robot has a force estimate and, on the twin, a plate at
``plate_z_m`` under every point (``plates``), else uses the model where there is one; a
backend with neither refuses probe runs. It writes ``touches.csv`` in place of
``pairs.csv``.

States: planned -> moving -> fitting -> done | refused (the fit is worse than the current
model on the held-out poses: never applied) | failed (a fault, e-stop, torque off, no
measurement) | aborted (``abort``: the motion stopped at once, the robot holds where it
is); done -> applied.

While a run is planned, moving or fitting it holds the controller's ``MotionOwner``
(app/control/owner.py): no other run, jog, goal or move can start, even between its poses,
until it ends or is aborted. The lifecycle (start, the thread, abort, the ending, close)
is app/procedures/lifecycle.py's; this module supplies the steps.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from app.calibration.fit import CalibrationError, FitResult, Plan, fit, plan
from app.calibration.pairs import write_pairs
from app.calibration.probe import (
    MIN_TOUCHES,
    PROBE_MODES,
    TOUCH_BEYOND_M,
    TOUCH_CLEARANCE_M,
    ProbeModel,
    ProbeResult,
    Touch,
    plate_under,
    probe_fit,
    probe_points,
    write_touches,
)
from app.config import LegSettings
from app.control.contact_commands import check_force, check_touch_speed
from app.control.controller import Controller
from app.control.errors import GoalRejected, MotionRefused
from app.control.state import Snapshot
from app.procedures.lifecycle import Ending, ProcedureManager, ProcedureRun, Stopped
from app.procedures.states import CALIBRATION_RUNNING, State
from hardware.calibration import JointCalibration, merge_joints, read_config, write_config
from hardware.encoder import RAD_PER_TICK
from kinematics import PerLegRotaryDelta, RotaryDelta

log = logging.getLogger(__name__)
Measure = Callable[[Snapshot], np.ndarray]
AVERAGE_TICKS = 20  # samples averaged at each rest (0.1 s at 200 Hz)
REST_TICKS = 40  # the joints must stay within REST_TOLERANCE_RAD this many ticks
REST_TOLERANCE_RAD = 2 * RAD_PER_TICK
REST_SPEED_RAD_S = 0.02  # and every joint's speed below this (about 1 deg/s)
MOVE_TIMEOUT_S = 60.0
MEASURE_WAIT_S = 3.0  # at rest, a measurement may be missing this long before the run fails
SPREAD_LIMIT_M = 0.003  # a reading this far from its rest's median: the run fails
RUNNING = CALIBRATION_RUNNING  # the states abort stops


def external(snapshot: Snapshot) -> np.ndarray:
    """The default measurement: the snapshot's external position (the twin's capture)."""
    return np.asarray(snapshot.external_m, dtype=np.float64)


MEASUREMENTS = ("external", "pose-input")


class Tracked(Protocol):
    """What a measurement needs of a pose tracker (app.world.poses.PoseTracker)."""

    def latest(self) -> tuple[Any, np.ndarray]: ...

    def health(self) -> tuple[str, float]: ...


def pose_input(tracker: Tracked) -> Measure:
    """A measurement from a motion-capture marker's poses in ``tracker`` (the pose input's
    "platform" body, app.world.poses.PoseTracker): the latest sample's position [m] (3,)
    while the tracker says "ok" (fresher than the world's ``stale_after_s``), NaN
    otherwise."""

    def measure(snapshot: Snapshot) -> np.ndarray:
        del snapshot  # the marker's own stream, not the loop's state
        sample, _ = tracker.latest()
        if sample is None or tracker.health()[0] != "ok":
            return np.full(3, np.nan)
        return np.asarray(sample.position_m, dtype=np.float64)

    return measure


_NO_MEASUREMENT = {
    "external": "measurement: no external measurement of the platform (ee.external_m): "
    "this backend has none; stream motion capture of the platform to the pose input and "
    "use measurement 'pose-input'",
    "pose-input": "measurement: no fresh motion-capture pose of the platform on the pose "
    "input (body 'platform'; its health: GET /api/mav/pose?body=platform)",
}


def _keep_measured(run: CalibrationRun) -> None:
    """A run that ended early keeps what it measured (pairs.csv, fit poses first; a
    `deltadash calibrate --from-csv` of enough of them still fits)."""
    if not run.measured or (run.folder / "pairs.csv").exists():
        return
    held = max(0, len(run.measured) - len(run.plan.fit_joints))
    try:
        write_pairs(run.folder / "pairs.csv", np.array(run.joints), np.array(run.measured), held)
    except Exception:  # never hides why the run ended
        log.exception("calibration run %s: its pairs could not be kept", run.run_id)


@dataclass
class CalibrationRun(ProcedureRun):
    """One calibration: its plan, progress, result and files (``folder``)."""

    run_id: str
    parameters: str
    poses: int
    plan: Plan
    folder: Path
    state: str = State.PLANNED
    pose: int = 0  # poses measured so far
    error: str | None = None
    result: FitResult | None = None
    joints: list[np.ndarray] = field(default_factory=list)
    measured: list[np.ndarray] = field(default_factory=list)
    source: str = "motion"
    measurement: str = "external"  # a motion run's measurement (MEASUREMENTS)
    plate_z_m: float | None = None
    fit_plate_z: bool = False
    probe_xy: np.ndarray | None = field(default=None, repr=False)  # (poses, 2) [m]
    probe: str | None = None  # a probe run's mode (PROBE_MODES)
    touch_speed_m_s: float | None = None  # a touch run's speed and set force (None: [contact])
    touch_force_n: float | None = None
    tip_offset_m: np.ndarray = field(default_factory=lambda: np.zeros(3), repr=False)
    # what the run is fitted against: the controller's model and joint offsets at its start
    nominal: PerLegRotaryDelta | None = field(default=None, repr=False)
    model_version: int = 0
    offsets_at_start_rad: np.ndarray = field(default_factory=lambda: np.zeros(3), repr=False)
    aborted: threading.Event = field(default_factory=threading.Event, repr=False)
    created_unix_s: float = field(default_factory=time.time)

    def summary(self) -> dict[str, Any]:
        """The list's entry (GET /api/calibration): id, state, what was fitted, RMSEs."""
        result = self.result
        return {
            "run_id": self.run_id,
            "state": self.state,
            "parameters_fitted": self.parameters,
            "source": self.source,
            "rmse_before_m": _num(result.rmse_before_m) if result else None,
            "rmse_after_m": _num(result.rmse_after_m) if result else None,
            "holdout_rmse_m": _num(result.holdout_rmse_m) if result else None,
            "error": self.error,
        }

    def view(self) -> dict[str, Any]:
        """The API's body (GET /api/calibration/{run_id}); SI units; NaN -> None."""
        obs = self.plan.observability
        result = self.result
        body: dict[str, Any] = {
            "run_id": self.run_id,
            "state": self.state,
            "kind": "calibration",
            "parameters_fitted": self.parameters,
            "progress": {"pose": self.pose, "poses": self.poses},
            "error": self.error,
            "parameters": result.parameters_out() if result else None,
            "rmse_before_m": _num(result.rmse_before_m) if result else None,
            "rmse_after_m": _num(result.rmse_after_m) if result else None,
            "holdout_rmse_before_m": _num(result.holdout_before_m) if result else None,
            "holdout_rmse_m": _num(result.holdout_rmse_m) if result else None,
            "condition_number": _num(obs.condition_number),
            "singular_values": [float(v) for v in obs.singular_values],
            "unobservable": list(obs.unobservable),
            "holdout_poses": len(self.plan.holdout_joints),
            "measurement_frame": (
                {"position_m": list(result.frame.position_m), "rpy_rad": list(result.frame.rpy_rad)}
                if result
                else None
            ),
            "files": sorted(p.name for p in self.folder.glob("*") if p.is_file()),
            "source": self.source,
            "measurement": self.measurement if self.source == "motion" else None,
            "plate_z_m": self.plate_z_m,
            "probe": self.probe,
            "plate_error_m": (
                result.plate_error_m
                if isinstance(result, ProbeResult) and result.plate_free
                else None
            ),
            "unobservable_combinations": list(obs.combinations),
        }
        return body


def _num(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


class CalibrationManager(ProcedureManager[CalibrationRun]):
    """Starts calibration runs on one controller and keeps them (in memory) by id; the
    lifecycle (abort, running, close, get) is ``ProcedureManager``'s."""

    kind, prefix, route = "calibration", "cal", "/api/calibration"
    running_states = RUNNING
    failures = (CalibrationError,)

    def __init__(
        self,
        controller: Controller,
        folder: Path,
        config_path: Path | None = None,
        measure: Measure = external,
        probe: Touch | None = None,
        pose_measure: Measure | None = None,
        plates: Sequence[Any] = (),
    ) -> None:
        super().__init__(controller, folder)
        self.config_path, self.probe = config_path, probe
        # the plates the backend knows are there (the twin's: hardware/sim/surfaces.py)
        self.plates = tuple(plates)
        # the measurements a motion run may use, by name (MEASUREMENTS)
        self.measures: dict[str, Measure] = {"external": measure}
        if pose_measure is not None:
            self.measures["pose-input"] = pose_measure

    def nominal(self) -> PerLegRotaryDelta:
        """The controller's model in use now as a per-leg one (what a run is fitted
        against: after a geometry apply, the fitted legs)."""
        return per_leg(self.controller.robot)

    def _allowed(self, joints: np.ndarray) -> np.ndarray:
        gate = self.controller.model.gate  # one model for every check
        robot = gate.robot
        ok = np.zeros(len(joints), dtype=bool)
        points = robot.fk(joints).points
        for k, q in enumerate(joints):
            try:
                gate.check_joints(q)
            except GoalRejected:
                continue
            ok[k] = gate.inside(points[k])
        return ok

    def list(self) -> list[CalibrationRun]:
        """This server's runs (kept in memory), newest first."""
        return sorted(self._runs.values(), key=lambda r: r.created_unix_s, reverse=True)

    def start(
        self,
        poses: int,
        parameters: str,
        source: str = "motion",
        plate_z_m: float | None = None,
        fit_plate_z: bool = False,
        measurement: str = "external",
        probe: str | None = None,
        touch_speed_m_s: float | None = None,
        touch_force_n: float | None = None,
    ) -> CalibrationRun:
        """Plan and start a run (returns at once; the thread moves the arm, or probes).

        source: "motion" (external measurement of the platform) or "probe" (touches of a
        flat plate at ``plate_z_m`` [m], base frame; ``fit_plate_z``: fit an error of that
        height too). measurement (motion runs): "external" (the backend's own, the twin's)
        or "pose-input" (a motion-capture marker on the platform, streamed to the pose
        input as body "platform"). probe (probe runs): "touch" (the arm touches the plate
        with the force-guided touch, at ``touch_speed_m_s`` [m/s] up to ``touch_force_n``
        [N], None: the ``[contact]`` defaults) or "model" (the twin's computed touches);
        None: "touch" where the robot has a force estimate and, on the twin, a plate at
        ``plate_z_m`` under the points, else "model" (module doc).

        Raises:
            CalibrationError: poses, parameters, source, measurement or plate that cannot be
                planned, or a probe run on a backend without a probe (422).
            MotionRefused: the robot may not move now, a run is in progress, or the chosen
                measurement has nothing fresh now (409).
        """
        with self._lock:
            # a run in progress, a procedure holding the robot, a test run, no motion now
            snap = self._may_start()
            model, offsets = self.controller.model, self.controller.joint_offsets_rad
            nominal = per_leg(model.robot)
            xy = None
            if source == "motion":
                self._require_measurement(measurement, snap)
                chosen = plan(nominal, poses, parameters, allowed=self._allowed)
            elif source == "probe":
                if probe is not None and probe not in PROBE_MODES:
                    raise CalibrationError(
                        f"probe: {probe!r} is not one of {', '.join(map(repr, PROBE_MODES))}"
                    )
                mode = self._probe_mode(probe, snap, plate_z_m, poses)
                tip = self._tip_offset() if mode == "touch" else np.zeros(3)
                if mode == "touch":
                    self._check_touch(touch_speed_m_s, touch_force_n)
                chosen, xy = self._plan_probe(
                    poses, parameters, plate_z_m, fit_plate_z, mode, tip[2]
                )
            else:
                raise CalibrationError(f"source: {source!r} is not 'motion' or 'probe'")

            def make(run_id: str, folder: Path) -> CalibrationRun:
                run = CalibrationRun(run_id, parameters, poses, chosen, folder)
                run.source, run.plate_z_m, run.fit_plate_z, run.probe_xy = (
                    source,
                    plate_z_m,
                    fit_plate_z,
                    xy,
                )
                run.measurement = measurement
                if source == "probe":
                    run.probe, run.tip_offset_m = mode, tip
                    run.touch_speed_m_s, run.touch_force_n = touch_speed_m_s, touch_force_n
                run.nominal, run.model_version = nominal, model.version
                run.offsets_at_start_rad = offsets
                return run

            return self._launch(make)

    def _require_measurement(self, measurement: str, snap: Snapshot) -> None:
        """A motion run starts only with a measurement that answers now."""
        if measurement not in MEASUREMENTS:
            raise CalibrationError(
                f"measurement: {measurement!r} is not one of {', '.join(MEASUREMENTS)}"
            )
        measure = self.measures.get(measurement)
        if measure is None:
            raise CalibrationError(f"measurement: {measurement!r} is not available here")
        if not np.isfinite(measure(snap)).all():
            raise MotionRefused(_NO_MEASUREMENT[measurement])

    def _tip_offset(self) -> np.ndarray:
        """The tool tip in the platform frame at wrist angle 0 [m] (3,): [tool] offset_m."""
        tool = getattr(getattr(self.controller, "settings", None), "tool", None)
        return np.asarray(getattr(tool, "offset_m", (0.0, 0.0, 0.0)), dtype=float)

    def _probe_mode(
        self, mode: str | None, snap: Snapshot, plate_z_m: float | None, poses: int
    ) -> str:
        """The probe mode a run of ``poses`` touches at ``plate_z_m`` [m] uses: ``mode``
        when it can, else the default (module doc), before anything is planned.

        Raises:
            CalibrationError: "touch" without a force estimate now, "model" (or neither)
                on a backend without a model probe (422).
        """
        contact = getattr(snap, "contact", None)
        estimate = contact is not None and bool(contact.valid)
        if mode == "model" and self.probe is None:
            raise CalibrationError(
                "probe: 'model' computes the touches from the twin's true model, and this "
                "backend has none: use 'touch'"
            )
        if mode is None:
            on_plate = self.probe is None
            if estimate and not on_plate and plate_z_m is not None and math.isfinite(plate_z_m):
                tip = self._tip_offset()
                try:  # the points a touch run would touch (with the tool tip)
                    tips = probe_points(self.nominal(), plate_z_m - tip[2], poses) + tip[:2]
                except CalibrationError:
                    tips = None  # the plan says why
                on_plate = tips is not None and plate_under(self.plates, plate_z_m, tips)
            mode = "touch" if estimate and on_plate else "model"
        if mode == "touch" and not estimate:
            reason = contact.reason if contact is not None else "none on this backend"
            raise CalibrationError(
                f"probe: 'touch' needs the contact force estimate, not valid now: {reason}"
            )
        if mode == "model" and self.probe is None:
            raise CalibrationError(
                "source: this backend has no probe (the simulated robot has one) nor a "
                "contact force estimate to touch with; use 'motion' with an external "
                "measurement"
            )
        return mode

    def _check_touch(self, speed_m_s: float | None, force_n: float | None) -> None:
        """A touch run's own speed [m/s] and set force [N], checked as the touch will.

        Raises:
            CalibrationError: naming the field: not a finite number > 0, a speed over
                0.1 m/s, a force not above contact.detect_force_n or over
                contact.force_limit_n (422).
        """
        contact = getattr(getattr(self.controller, "settings", None), "contact", None)
        try:
            if speed_m_s is not None:
                check_touch_speed(speed_m_s, "touch_speed_m_s")
            if force_n is not None and contact is not None:
                check_force(force_n, contact, "touch_force_n")
                if force_n <= contact.detect_force_n:
                    raise ValueError(
                        f"touch_force_n: {force_n:g} N is not above the contact threshold "
                        f"{contact.detect_force_n:g} N (contact.detect_force_n)"
                    )
        except ValueError as exc:
            raise CalibrationError(str(exc)) from None

    def _plan_probe(
        self,
        poses: int,
        parameters: str,
        plate_z_m: float | None,
        fit_plate_z: bool,
        mode: str | None = "model",
        tip_z_m: float = 0.0,
    ) -> tuple[Plan, np.ndarray]:
        """Probe points over the plate (fit ones, then every fourth held out), the joints
        the nominal model would touch them with, and what those touches can tell. A touch
        (``mode`` not "model") touches with the tool tip, ``tip_z_m`` [m] from the
        platform along z: the platform is at plate_z_m - tip_z_m; the points are the
        platform's."""
        if mode == "model" and self.probe is None:
            raise CalibrationError(
                "source: this backend has no probe (the simulated robot has one); use "
                "'motion' with an external measurement"
            )
        if plate_z_m is None or not math.isfinite(plate_z_m):
            raise CalibrationError("plate_z_m: a probe run needs the plate's height [m]")
        plate_z_m = plate_z_m - tip_z_m  # the platform's height at contact
        nominal = self.nominal()
        model = ProbeModel(nominal, parameters, fit_plate_z)
        xy = probe_points(nominal, plate_z_m, poses)
        held = np.arange(poses) % 4 == 3  # every fourth, spread over the plate
        need = max(MIN_TOUCHES, 2 * len(model.names))
        if poses - held.sum() < need or held.sum() < 1:
            raise CalibrationError(
                f"poses: {poses} touches are too few to fit {len(model.names)} parameters "
                f"from heights (at least {math.ceil(need * 4 / 3)})"
            )
        xy = np.vstack([xy[~held], xy[held]])
        joints = nominal.ik(np.column_stack([xy, np.full(poses, plate_z_m)])).joints
        allowed = self._allowed(joints)
        if not allowed.all():
            raise CalibrationError(
                f"plate_z_m: {int((~allowed).sum())} of {poses} touch points at "
                f"{plate_z_m} m are outside the joint limits or the safe workspace"
            )
        n_held = int(held.sum())
        fit_joints, holdout_joints = joints[: poses - n_held], joints[poses - n_held :]
        return Plan(fit_joints, holdout_joints, model.observability(model.initial, fit_joints)), xy

    # ---- the run's thread: its steps ----
    def _steps(self, run: CalibrationRun) -> Ending:
        """Moves, measures and fits; the state the run ends in (done, refused), with its
        error. Raises Stopped (and the like) to fail the run."""
        if run.source == "probe":
            return self._steps_probe(run)
        run.advance(State.MOVING)
        for q in run.plan.joints:
            joints, measured = self._visit(run, q)
            run.joints.append(joints)
            run.measured.append(measured)
            run.pose += 1
        run.advance(State.FITTING)
        holdout = len(run.plan.holdout_joints)
        joints, measured = np.array(run.joints), np.array(run.measured)
        write_pairs(run.folder / "pairs.csv", joints, measured, holdout)
        assert run.nominal is not None
        result = fit(run.nominal, joints, measured, holdout, run.parameters)
        run.result = result
        from app.calibration.report import write_report  # matplotlib: only when needed

        write_report(run.folder / "report.png", result, f"calibration {run.run_id}")
        return _judge(result)

    def _steps_probe(self, run: CalibrationRun) -> Ending:
        """A probe run's steps: the touches (the arm touches the plate, or, in "model"
        mode, they are computed and it is not moved), the fit."""
        assert run.probe_xy is not None and run.plate_z_m is not None
        run.advance(State.MOVING)
        if run.probe == "touch":
            joints = self._touches(run)
        else:
            assert self.probe is not None
            joints = self.probe(run.probe_xy, run.plate_z_m, 0)
            run.joints = list(joints)
            run.pose = len(joints)
        run.advance(State.FITTING)
        holdout = len(run.plan.holdout_joints)
        # the platform's height at each touch (the tool tip's is plate_z_m)
        plate = np.full(len(joints), run.plate_z_m - run.tip_offset_m[2])
        write_touches(run.folder / "touches.csv", joints, plate, holdout)
        assert run.nominal is not None
        result = probe_fit(run.nominal, joints, plate, holdout, run.parameters, run.fit_plate_z)
        run.result = result
        from app.calibration.report import write_report  # matplotlib: only when needed

        title = f"probe calibration {run.run_id} (plate at z = {run.plate_z_m * 1e3:.1f} mm)"
        write_report(run.folder / "report.png", result, title)
        return _judge(result)

    def _touches(self, run: CalibrationRun) -> np.ndarray:
        """Touch the plate at each of the run's points (module doc); the legs' joints as
        read at each contact (poses, 3) [rad].

        Raises:
            Stopped: naming the point: a touch ended without contact, a move or touch
                refused, a fault, e-stop, torque off, an abort, a timeout.
        """
        assert run.probe_xy is not None and run.plate_z_m is not None
        tips = run.probe_xy + run.tip_offset_m[:2]
        above = run.plate_z_m + TOUCH_CLEARANCE_M
        for k, (x, y) in enumerate(tips):
            where = f"touch {k + 1} of {len(tips)} at ({x * 1e3:.1f}, {y * 1e3:.1f}) mm"
            try:
                run.joints.append(self._touch_once(run, np.array([x, y, above])))
            except (Stopped, GoalRejected, MotionRefused, ValueError) as exc:
                raise Stopped(f"{where}: {exc}") from None
            run.pose += 1
        return np.array(run.joints)

    def _touch_once(self, run: CalibrationRun, above_m: np.ndarray) -> np.ndarray:
        """Move the tip to ``above_m`` (3,) [m], touch straight down and back up; the legs'
        joints as read when contact was seen (3,) [rad]."""
        ctl = self.controller
        ctl.move(point=above_m).result(timeout=MOVE_TIMEOUT_S)
        self._wait(run, "the move above the plate to end", _idle, MOVE_TIMEOUT_S)
        values: dict[str, Any] = {
            "max_travel_m": TOUCH_CLEARANCE_M + TOUCH_BEYOND_M,
            "retract_m": TOUCH_CLEARANCE_M,
        }
        if run.touch_speed_m_s is not None:
            values["speed_m_s"] = run.touch_speed_m_s
        if run.touch_force_n is not None:
            values["force_n"] = run.touch_force_n
        started = ctl.touch([0.0, 0.0, -1.0], **values).result(timeout=MOVE_TIMEOUT_S)
        source_id = started["source_id"]

        def ended(snap: Snapshot) -> bool:
            touch = snap.touch
            return (
                touch is not None
                and touch.source_id == source_id
                and touch.outcome != "touching"
                and snap.mode == "idle"
            )

        snap = self._wait(run, "the touch to end", ended, TOUCH_TIMEOUT_S)
        touch = snap.touch
        assert touch is not None
        joints = np.asarray(touch.joints_at_contact_rad, dtype=float)
        if touch.outcome != "contact" or not np.isfinite(joints).all():
            raise Stopped(
                f"the touch ended {touch.outcome!r} (travel {touch.travel_m * 1e3:.1f} mm, "
                f"peak force {touch.peak_force_n:.2f} N): no plate at "
                f"plate_z_m = {run.plate_z_m:g} m there, or the touch was stopped"
            )
        return joints

    def _ended_early(self, run: CalibrationRun) -> None:
        _keep_measured(run)  # a probe run has no measured pairs: nothing to keep
        path = run.folder / "touches.csv"
        if run.source == "probe" and run.joints and not path.exists() and run.plate_z_m:
            plate = np.full(len(run.joints), run.plate_z_m - run.tip_offset_m[2])
            try:  # the touches made so far, all as fit rows
                write_touches(path, np.array(run.joints), plate, 0)
            except Exception:  # never hides why the run ended
                log.exception("calibration run %s: its touches could not be kept", run.run_id)

    def _fresh(self, after: int) -> Callable[[Snapshot], bool]:
        return lambda snap: snap.tick > after

    def _visit(self, run: CalibrationRun, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Move to ``q`` [rad], wait for rest, average joints and measurement; (3,), (3,)."""
        started = self.controller.move(joints=q, joint_space=True).result(timeout=MOVE_TIMEOUT_S)
        del started
        self._wait(run, "the move to end", lambda s: s.mode == "idle", MOVE_TIMEOUT_S)
        window: list[np.ndarray] = []
        last = -1

        def rested(snap: Snapshot) -> bool:
            nonlocal last
            if snap.tick == last:
                return False
            last = snap.tick
            if snap.stale:  # a simulator that stalled: its old state says nothing of rest
                return False
            window.append(snap.joints_measured_rad)
            del window[:-REST_TICKS]
            spread = np.ptp(np.array(window), axis=0)
            moving = np.abs(snap.velocity_rad_s) > REST_SPEED_RAD_S  # NaN (unknown): not
            return (
                len(window) == REST_TICKS
                and bool((spread <= REST_TOLERANCE_RAD).all())
                and not moving.any()
            )

        self._wait(run, "the arm to come to rest", rested, MOVE_TIMEOUT_S)
        joints, measured = [], []
        measure, answered_s = self.measures[run.measurement], time.monotonic()
        while len(joints) < AVERAGE_TICKS:
            snap = self._wait(run, "a fresh tick", self._fresh(last), 5.0)
            last = snap.tick
            if snap.stale:
                continue  # the same state again: it would count twice
            y = measure(snap)
            if not np.isfinite(y).all():  # a stream's hiccup: skip the tick, for a while
                if time.monotonic() - answered_s > MEASURE_WAIT_S:
                    raise Stopped(_NO_MEASUREMENT[run.measurement])
                continue
            answered_s = time.monotonic()
            joints.append(snap.joints_measured_rad)
            measured.append(y)
        seen = np.array(measured)
        spread = float(np.linalg.norm(seen - np.median(seen, axis=0), axis=1).max())
        if spread > SPREAD_LIMIT_M:
            raise Stopped(
                f"measurement: at pose {run.pose + 1} the readings of the resting arm spread "
                f"{spread * 1e3:.1f} mm (over {SPREAD_LIMIT_M * 1e3:g} mm): a marker swapped "
                "or occluded, or the base moving?"
            )
        return np.mean(joints, axis=0), np.mean(seen, axis=0)

    # ---- apply ----
    def apply(self, run_id: str, settings_joints: list[JointCalibration]) -> dict[str, Any]:
        """Make the controller use the run's result and write it to the config file when
        one is in use; the body says what was done.

        An ``offsets`` run: the joint offsets (added to those in use). A ``geometry`` run:
        the offsets and each leg's fitted L, l, R, r as the controller's robot model (its
        gate, IK, FK and everything that reads them), written as ``[robot.legs]``. Nothing
        moves (``Controller.use_model``).

        Raises:
            MotionRefused: the run is not done (refused, failed, running), it was fitted
                against another model or other joint offsets than those in use now (a
                calibration applied since), or a motion is running (409).
        """
        run = self._runs[run_id]
        with self._lock:  # one apply at a time: each checks what the last one left
            if run.state == "refused":
                raise MotionRefused(f"run {run_id} was refused: {run.error}")
            if run.state == "applied":
                raise MotionRefused(f"run {run_id} is applied already")
            if run.state != "done" or run.result is None:
                raise MotionRefused(f"run {run_id} is {run.state}: only a done run can be applied")
            if run.source == "probe" and run.parameters == "geometry":
                raise MotionRefused(
                    "parameters: a probe's touch heights cannot pin the legs' geometry "
                    "(see unobservable_combinations): its geometry is not applied; apply "
                    "offsets from a probe run, or fit geometry with motion capture"
                )
            model = self.controller.model
            in_use = self.controller.joint_offsets_rad
            if model.version != run.model_version or not np.array_equal(
                in_use, run.offsets_at_start_rad
            ):
                raise MotionRefused(
                    f"run {run_id} was fitted against the robot model and joint offsets in "
                    f"use when it started; a calibration applied since changed them (model "
                    f"from {model.origin}): calibrate again"
                )
            fitted = run.result.robot
            total = in_use + np.array(fitted.joint_offsets_rad)
            robot = None
            if run.parameters == "geometry":
                robot = fitted.with_values(joint_offsets_rad=(0.0, 0.0, 0.0))
                applied = self.controller.use_model(robot, total, f"calibration {run_id}")
                applied.result(timeout=APPLY_TIMEOUT_S)
                offsets = self.controller.joint_offsets_rad.tolist()
            else:
                offsets = self.controller.set_joint_offsets(total).result(timeout=5.0)
            written = None
            if self.config_path is not None:
                write_calibration(self.config_path, settings_joints, total, robot)
                written = str(self.config_path)
            run.state = State.APPLIED
        self._save(run)
        return {
            "run_id": run_id,
            "parameters_applied": run.parameters,
            "joint_offsets_rad": offsets,
            "robot": self.controller.model.describe(),
            "config_written": written,
        }


APPLY_TIMEOUT_S = 5.0
TOUCH_TIMEOUT_S = 60.0  # a touch, its dwell and its retract [s]


def _idle(snap: Snapshot) -> bool:
    return snap.mode == "idle"


def per_leg(robot: Any) -> PerLegRotaryDelta:
    """``robot`` (the controller's model) as a per-leg one: a symmetric rotary Delta's
    equal legs, or the per-leg robot itself.

    Raises:
        CalibrationError: for a linear Delta.
    """
    if isinstance(robot, PerLegRotaryDelta):
        return robot
    if not isinstance(robot, RotaryDelta):
        raise CalibrationError("robot.type: calibration models rotary Deltas only")
    return PerLegRotaryDelta.from_symmetric(robot)


def write_calibration(
    path: Path,
    joints: list[JointCalibration],
    offsets_rad: Any,
    robot: PerLegRotaryDelta | None = None,
) -> None:
    """Write an applied calibration into the TOML file ``path``, keeping everything else:
    ``offsets_rad`` [rad] (3,) as the joints' new zero offsets (``offsets_into_zero_ticks``
    of ``joints``, the records the server started with) and, for a geometry fit, ``robot``'s
    legs as ``[robot.legs]`` (app/config.py ``LegSettings``), read back at start. One
    atomic write: the file never holds the offsets of one fit and the legs of another."""
    config = merge_joints(read_config(path), offsets_into_zero_ticks(joints, offsets_rad))
    if robot is not None:
        section = config.setdefault("robot", {})
        section["legs"] = {k: list(v) for k, v in LegSettings.of(robot).model_dump().items()}
    write_config(path, config)


def _judge(result: FitResult) -> Ending:
    """done when the fit beats the current model on the held-out data, else refused."""
    if result.better:
        return State.DONE, None
    return (
        State.REFUSED,
        f"the fit is worse on the held-out poses than the current model "
        f"({result.holdout_rmse_m * 1e3:.3f} mm vs "
        f"{result.holdout_before_m * 1e3:.3f} mm): it is not offered",
    )


def offsets_into_zero_ticks(
    joints: list[JointCalibration], offsets_rad: Any
) -> list[JointCalibration]:
    """Joint records whose zero offsets read ``q + o`` where ``joints`` read q:
    zero' = zero - direction * round(o / RAD_PER_TICK) (hardware/calibration.py's relation
    ticks = zero + direction * theta / RAD_PER_TICK)."""
    return [
        replace(
            j, zero_offset_ticks=j.zero_offset_ticks - j.direction * round(float(o) / RAD_PER_TICK)
        )
        for j, o in zip(joints, offsets_rad, strict=True)
    ]

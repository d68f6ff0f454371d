"""The tuning run on the robot: identify each joint, suggest gains, apply, revert.

A ``TuningRun`` (its own thread, like app/calibration/procedure.py's) moves the arm to the
runs' start point, records a step run and a chirp run through the run manager (the same
``POST /api/tests/step`` and ``/chirp`` paths, logs under the runs folder), fits each chosen
joint's model from them (`identify.identify`, the Bode plot in ``bode.png``), and checks
the rule's candidate gains for the target on the twin (`twin_check.offer`: the thesis
sinusoid plain and with the loop's lead, a z step, rest at five points, under the loop's
lead time and gravity offset settings) before it suggests the one the check offers (the
first to pass issue 21's limits, else the closest, saying so); `gains.predict` gives what
the model predicts of it against the gains now in use. The check is tens of seconds of
CPU: it runs in a worker process at a lower priority (app/programs/workers.py's
``ProgramWorkers``, one slot, made for the check and closed after it), never in the
server's process, so the 200 Hz loop is not held by it; an abort or the server stopping
kills that worker at once. Applying writes the suggested gains of the tuned joints to the
servos through the controller (the others keep theirs), into the config file's joint
records when the server runs from one (written to the servos when it starts), and keeps
the previous ones for `revert`.

The model is identified under the gains in use when the run starts: it is a P-only loop's
(`gains.Plant.of`), so a run is refused while tuned gains are in use (revert first).

States: planned -> moving -> step -> chirp -> fitting -> checking -> done | failed (a
fault, e-stop, torque off, a run that did not finish, a fit that failed, a twin check that
did not come back: ``error`` says why; nothing unchecked is suggested) | aborted
(``abort``: the motion, or the step or chirp run, stopped at once; the robot holds where
it is; a twin check in flight is killed); done -> applied.

While it moves the arm (planned, moving, step, chirp) a run holds the controller's
``MotionOwner`` (app/control/owner.py): nothing else moves the robot, not even between its
step and chirp runs, until it ends or is aborted. Once the chirp run is recorded the run
needs the robot no more: it lets go of it before fitting and checking, which take no
motion (the operator may move the arm meanwhile; another tuning run waits for this one).
The lifecycle (start, the thread, abort, the ending, close) is
app/procedures/lifecycle.py's; this module supplies the steps.
"""

from __future__ import annotations

import logging
import math
import threading
import time
import tomllib
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from app.config import Settings
from app.control.controller import Controller
from app.control.errors import MotionRefused
from app.procedures.lifecycle import Ending, ProcedureManager, ProcedureRun, Stopped
from app.procedures.states import TUNING_RUNNING, State
from app.programs import workers
from app.programs.workers import (
    ChecksBusy,
    ChecksStopped,
    ProgramWorkers,
    WorkerError,
    WorkerTimeout,
)
from app.runs.logs import read_csv_rows
from app.runs.manager import RunManager
from app.runs.paths import ChirpParams, StepParams
from app.tuning.gains import Plant, Suggestion, Target, TuningError, predict
from app.tuning.identify import JOINTS, IdentificationError, JointFit, identify
from app.tuning.twin_check import Candidate, Offer, OfferJob, joint_gains, run_offer
from hardware.bus import PositionGains
from hardware.calibration import SECTION, save

log = logging.getLogger(__name__)
workers.preload(run_offer.__module__)  # the twin check's worker imports it: once, not each
START_M = (0.0, 0.0, -0.24)  # where both runs start (the runs' default offset) [m]
STEP = StepParams(size_m=0.004, duration_s=1.5, offset_m=START_M)
CHIRP = ChirpParams(amplitude_m=0.003, f0_hz=0.5, f1_hz=8.0, duration_s=6.0, offset_m=START_M)
MOVE_TIMEOUT_S = 60.0
RUN_TIMEOUT_S = 120.0  # a starved twin runs slower than the wall clock
RUNNING = TUNING_RUNNING  # abort stops these
CHECK_TIMEOUT_S = 900.0  # the twin check's worker is killed beyond this (a loaded machine)
TwinCheck = Callable[[OfferJob], Offer]


def gains_out(gains: PositionGains) -> dict[str, int]:
    """The API's form of a servo's gains (`PositionGains.as_dict`)."""
    return gains.as_dict()


def _finite(values: dict[str, float]) -> dict[str, float | None]:
    return {k: (float(v) if math.isfinite(v) else None) for k, v in values.items()}


def candidate_out(number: int, c: Candidate, servo_ids: tuple[int, ...]) -> dict[str, Any]:
    """One checked candidate for the API: its number (1: the first tried), the variant of
    the target the rule was given, the gains per servo id (all three legs: those not tuned
    keep theirs) and the twin's figures (SI: m, fractions, %)."""
    v = c.verdict
    return {
        "candidate": number,
        "target": {
            "pwm_fraction": c.target.pwm_fraction,
            "overshoot_pct": c.target.overshoot_pct,
            "integral": c.target.integral,
        },
        "gains": {str(sid): gains_out(g) for sid, g in zip(servo_ids, c.gains, strict=True)},
        **{
            kind: {"rmse_m": list(t.rmse_m), "peak_pwm": t.peak_pwm, "at_limit": t.at_limit}
            for kind, t in (("plain", v.plain), ("lead", v.lead))
        },
        "overshoot_pct": v.overshoot_pct,
        "rest_m": list(v.rest_m),
        "long_move": {
            "overshoot_m": list(v.long.overshoot_m),
            "settle_s": list(v.long.settle_s),
        },
        "failed": list(v.failed),
        "passes": v.passes,
    }


def checked_out(offer: Offer, job: OfferJob, servo_ids: tuple[int, ...]) -> dict[str, Any]:
    """What the twin check found, for the API: every candidate, the one chosen (its
    number), why, whether it meets issue 21's goal, and the check's conditions."""
    return {
        "met_goal": offer.met,
        "chosen": offer.chosen + 1,
        "reason": offer.reason,
        "lead_s": job.lead_s,
        "gravity_compensation": job.gravity,
        "seconds": job.seconds,
        "limits": asdict(job.limits),
        "candidates": [candidate_out(k + 1, c, servo_ids) for k, c in enumerate(offer.tried)],
    }


@dataclass
class TuningRun(ProcedureRun):
    """One tuning: the joints (1..3) and target, progress, models and suggestions per
    joint, and its files (``folder``)."""

    run_id: str
    joints: tuple[int, ...]
    target: Target
    servo_ids: tuple[int, ...]  # the legs' servo ids, joint order
    current: dict[int, PositionGains]  # the gains in use when it started, per servo id
    folder: Path
    state: str = State.PLANNED
    error: str | None = None
    runs: dict[str, str] = field(default_factory=dict)  # kind -> run id
    fits: list[JointFit] = field(default_factory=list)
    suggestions: dict[int, Suggestion] = field(default_factory=dict)  # servo id -> suggestion
    predicted_now: dict[int, dict[str, float | None]] = field(default_factory=dict)
    check: OfferJob | None = None  # the twin check asked for
    offer: Offer | None = None  # what it found (the suggestions are its chosen gains)
    aborted: threading.Event = field(default_factory=threading.Event, repr=False)
    created_unix_s: float = field(default_factory=time.time)

    def servo(self, joint: int) -> int:
        return self.servo_ids[joint - 1]

    def view(self) -> dict[str, Any]:
        """The API's body (GET /api/tuning/{run_id}); SI units, gains in register units."""
        return {
            "run_id": self.run_id,
            "state": self.state,
            "joints": list(self.joints),
            "target": asdict(self.target),
            "error": self.error,
            "runs": dict(self.runs),
            "model": {
                str(self.servo(f.joint)): {
                    "joint": f.joint,
                    **_finite(f.model.as_dict()),
                    "rmse_rad": f.rmse_rad,
                    "nrmse": f.nrmse,
                    "samples": f.samples,
                }
                for f in self.fits
            },
            "suggested": {str(sid): gains_out(s.gains) for sid, s in self.suggestions.items()},
            "predicted": {
                str(sid): {
                    "suggested": _finite(s.prediction.as_dict()),
                    "current": self.predicted_now.get(sid),
                    "crossover_target_hz": s.crossover_hz,
                    "meets_target": s.meets_target,
                }
                for sid, s in self.suggestions.items()
            },
            "checked": (
                None
                if self.offer is None or self.check is None
                else checked_out(self.offer, self.check, self.servo_ids)
            ),
            "files": sorted(p.name for p in self.folder.glob("*") if p.is_file()),
        }


class TuningManager(ProcedureManager[TuningRun]):
    """Starts tuning runs on one controller (recording through ``runs``), keeps them in
    memory by id, applies one and reverts it; the lifecycle (abort, running, close, get) is
    ``ProcedureManager``'s: an abort also stops the step or chirp run and kills a twin
    check in flight."""

    kind, prefix, route = "tuning", "tune", "/api/tuning"
    running_states = RUNNING
    failures = (IdentificationError, TuningError)
    poll_s = 0.01

    def __init__(
        self,
        controller: Controller,
        runs: RunManager,
        folder: Path,
        config_path: Path | None = None,
        twin_check: TwinCheck | None = None,
    ) -> None:
        super().__init__(controller, folder)
        self.runs, self.config_path = runs, config_path
        # the twin check of the candidates: None, in a worker process (`_check_in_worker`)
        self.twin_check = twin_check
        self._workers: ProgramWorkers | None = None  # the check's worker, while it runs
        self._previous: list[dict[int, PositionGains]] = []  # what apply replaced, last on top

    def _interrupt(self) -> None:
        if self._workers is not None:
            self._workers.close()  # the check ends at once (ChecksStopped)

    def _halt(self, run: TuningRun) -> None:
        for recorded in run.runs.values():  # the step or chirp run, if one is running
            self.runs.abort(recorded, f"tuning run {run.run_id} aborted")
        self._stop_motion()

    def list(self) -> list[TuningRun]:
        """This server's runs (kept in memory), newest first."""
        return sorted(self._runs.values(), key=lambda r: r.created_unix_s, reverse=True)

    def summary(self, run: TuningRun) -> dict[str, Any]:
        """The list's entry (GET /api/tuning): id, state, joints, whether the suggested
        gains met the goal on the twin (None until checked), error."""
        return {
            "run_id": run.run_id,
            "state": run.state,
            "joints": list(run.joints),
            "met_goal": None if run.offer is None else bool(run.offer.met),
            "error": run.error,
        }

    def start(self, joints: tuple[int, ...], target: Target) -> TuningRun:
        """Start a run (returns at once; its thread moves the arm).

        Raises:
            TuningError: joints that are not 1..3, none, or repeated (422).
            MotionRefused: the robot may not move now, a run is in progress, or tuned
                gains are in use (409).
        """
        if not joints or len(set(joints)) != len(joints) or not set(joints) <= set(JOINTS):
            raise TuningError(f"joints = {list(joints)}: distinct joints of {list(JOINTS)}")
        with self._lock:
            # a run in progress, a procedure holding the robot, a test run, no motion now
            self._may_start()
            current = self.controller.gains
            if any(g.i or g.d for g in current.values()):
                raise MotionRefused(
                    "tuned gains are in use: the model is identified under P only; "
                    "POST /api/tuning/revert first"
                )
            servo_ids = tuple(self.controller.servo_ids)
            return self._launch(
                lambda run_id, folder: TuningRun(
                    run_id, tuple(joints), target, servo_ids, current, folder
                )
            )

    # ---- the run's thread: its steps ----
    def _steps(self, run: TuningRun) -> Ending:
        """Records, fits and checks; the state the run ends in (done), with its error.
        Raises Stopped (and the like) to fail the run."""
        logs = {}
        for kind, params in ((State.STEP, STEP), (State.CHIRP, CHIRP)):
            run.advance(State.MOVING)
            self._move_to_start(run)
            run.advance(kind)
            logs[kind] = self._record(run, kind.value, params)
        self._let_go()  # no more motion: fitting and checking need no robot
        run.advance(State.FITTING)
        chirp = (CHIRP.f0_hz, CHIRP.f1_hz, CHIRP.duration_s)
        fits, bodes = identify(
            read_csv_rows(logs[State.STEP]), read_csv_rows(logs[State.CHIRP]), chirp, run.joints
        )
        run.fits = fits
        from app.tuning.identify import bode_figure  # matplotlib's figure: only here

        bode_figure(fits, bodes, run.folder / "bode.png")
        self._suggest(run)
        return State.DONE, None

    def _suggest(self, run: TuningRun) -> None:
        """The fitted joints' candidate gains checked on the twin (state ``checking``);
        the suggestions are the gains the check offers, with the model's prediction of
        them and of the gains in use. Raises Stopped when the check did not come back
        (aborted, the server stopping, its worker killed or timed out)."""
        plants = {f.joint: Plant.of(f.model, run.current[run.servo(f.joint)].p) for f in run.fits}
        settings = self.controller.settings
        run.check = OfferJob(
            plants,
            run.target,
            current=joint_gains([run.current[sid] for sid in run.servo_ids]),
            lead_s=settings.runs.feedforward_lead_s,
            gravity=self.controller.gravity is not None,  # as the loop does
        )
        run.advance(State.CHECKING)
        if self.twin_check is not None:
            offered = self.twin_check(run.check)
        else:
            offered = self._check_in_worker(run.check, run.aborted)
        if run.aborted.is_set():  # while it checked: nothing is suggested
            raise Stopped("aborted by the operator")
        suggestions = {}
        for joint, plant in plants.items():
            sid = run.servo(joint)
            s = offered.candidate.suggestions.get(joint)  # the rule's, for the chosen variant
            if s is None or s.gains != offered.gains[joint - 1]:
                raise TuningError(
                    f"joint {joint}: the check offered {offered.gains[joint - 1]} without the "
                    "rule's suggestion of it (internal error)"
                )
            suggestions[sid] = s
            now = predict(plant, run.current[sid], run.target.step_rad)
            run.predicted_now[sid] = _finite(now.as_dict())
        run.offer, run.suggestions = offered, suggestions

    def _check_in_worker(self, job: OfferJob, aborted: threading.Event) -> Offer:
        """`twin_check.run_offer` in a worker process of its own (``ProgramWorkers``, one
        slot, nice +10), killed by `abort` (which sets `aborted` under the same lock) or
        `close`."""
        workers = ProgramWorkers(self.controller.settings, slots=1, timeout_s=CHECK_TIMEOUT_S)
        with self._lock:
            if self._stop.is_set():
                raise Stopped("the server is shutting down")
            if aborted.is_set():
                raise Stopped("aborted by the operator")
            self._workers = workers
        try:
            return workers.call(run_offer, job)
        except (ChecksStopped, ChecksBusy):  # closed while running, or before it started
            raise Stopped(
                "the twin check was stopped (the run aborted, or the server stopping): "
                "nothing is suggested"
            ) from None
        except WorkerTimeout:
            raise Stopped(
                f"the twin check took longer than {CHECK_TIMEOUT_S:g} s: its worker was "
                "stopped and nothing is suggested unchecked"
            ) from None
        except WorkerError:
            raise Stopped(
                "the twin check's worker process ended before answering (killed, or out of "
                "memory): nothing is suggested unchecked"
            ) from None
        finally:
            with self._lock:
                self._workers = None
            workers.close()

    def _move_to_start(self, run: TuningRun) -> None:
        self.controller.move(point=START_M).result(timeout=MOVE_TIMEOUT_S)
        self._wait(
            run,
            "the move to the start point",
            lambda snap: snap.mode == "idle",
            MOVE_TIMEOUT_S,
            met_first=True,
        )

    def _record(self, run: TuningRun, kind: str, params: Any) -> Path:
        """Run `params` through the run manager; the log's path once it is done."""
        recorded = self.runs.start(params, kind)
        run.runs[kind] = recorded.run_id
        ended = lambda _: recorded.state != "running"  # noqa: E731
        self._wait(run, f"the {kind} run", ended, RUN_TIMEOUT_S, met_first=True)
        if recorded.state != "done":
            raise Stopped(f"the {kind} run {recorded.run_id} ended {recorded.state}")
        return recorded.folder / "log.csv"

    # ---- apply and revert ----
    def apply(self, run_id: str, confirm_missed: bool = False) -> dict[str, Any]:
        """The servos of the run's joints use its suggested gains from now on (the others
        keep theirs); the gains replaced are kept for `revert`. Gains that miss the goal on
        the twin (``met_goal`` false) are applied only with ``confirm_missed``: the
        operator has been told what they miss.

        Raises:
            MotionRefused: the run is not done (running, failed, applied already), its
                gains miss the goal and ``confirm_missed`` is false (the message says
                what they miss), or a motion is running (409).
        """
        run = self._runs[run_id]
        if run.state == "applied":
            raise MotionRefused(f"run {run_id} is applied already")
        if run.state != "done":
            raise MotionRefused(f"run {run_id} is {run.state}: only a done run can be applied")
        offer = run.offer
        if offer is not None and not offer.met and not confirm_missed:
            missed = ", ".join(offer.verdict.failed) or "the goal"
            raise MotionRefused(
                f"run {run_id}'s gains miss the goal on the twin ({missed}; {offer.reason}): "
                "apply them anyway with confirm_missed = true (deltadash tune "
                "--confirm-missed), or keep the gains in use"
            )
        with self._lock:
            before = self.controller.gains
            wanted = {**before, **{sid: s.gains for sid, s in run.suggestions.items()}}
            in_use = self.controller.set_gains(wanted).result(timeout=5.0)
            self._previous.append(before)
            run.state = State.APPLIED
            written = self._write_config(in_use)
        self._save(run)
        gains = {str(k): gains_out(g) for k, g in in_use.items()}
        return {"run_id": run_id, "gains": gains, "config_written": written}

    @property
    def revertable(self) -> bool:
        """An apply or a write that `revert` would undo."""
        return bool(self._previous)

    def write(self, servo_id: int, gains: PositionGains) -> dict[str, Any]:
        """One leg servo's gains from the operator (the servo panel, register units already
        checked against the control table): written to it, the other legs keep theirs;
        the gains replaced are kept for `revert`, as an apply's are.

        Raises:
            KeyError: ``servo_id`` is not a leg's (404).
            MotionRefused: a tuning run or a test run is in progress, a procedure holds
                the robot, or a motion is running (409).
        """
        with self._lock:
            if self.running():
                going = [r.run_id for r in self._runs.values() if r.state in RUNNING]
                how = f"; POST /api/tuning/{going[-1]}/abort to stop it" if going else ""
                name = f"tuning run {going[-1]}" if going else "a tuning run"
                raise MotionRefused(f"{name} is in progress: gains change once it ends{how}")
            if (other := self.controller.owner.busy()) is not None:  # a procedure, a run
                raise MotionRefused(other)
            before = self.controller.gains
            if servo_id not in before:
                raise KeyError(servo_id)
            wanted = {**before, servo_id: gains}
            in_use = self.controller.set_gains(wanted).result(timeout=5.0)
            self._previous.append(before)
            written = self._write_config(in_use)
        gains_now = {str(k): gains_out(g) for k, g in in_use.items()}
        return {"gains": gains_now, "config_written": written}

    def revert(self) -> dict[str, Any]:
        """The gains in use before the last apply or write, back on the servos.

        Raises MotionRefused: nothing was applied or written, or a motion is running
        (409)."""
        with self._lock:
            if not self._previous:
                raise MotionRefused("no applied tuning or written gains to revert")
            in_use = self.controller.set_gains(self._previous[-1]).result(timeout=5.0)
            self._previous.pop()
            written = self._write_config(in_use)
        gains = {str(k): gains_out(g) for k, g in in_use.items()}
        return {"gains": gains, "config_written": written}

    def _write_config(self, gains: dict[int, PositionGains]) -> str | None:
        """The gains into the config file's joint records, when the server runs from one
        (the server then writes them to the servos when it starts); its path, or None."""
        if self.config_path is None:
            return None
        save_gains(self.config_path, self.controller.settings, gains)
        return str(self.config_path)


def save_gains(path: Path, settings: Settings, gains: dict[int, PositionGains]) -> None:
    """Write `gains` (per leg servo id) as each ``[[hardware.joints]]`` record's ``gains``
    in the TOML file `path`, keeping everything else; joint records the file lacks are
    written from `settings` (the calibration in use) first."""
    if not path.exists() or not _has_joint_records(path):
        save(path, [joint.calibration() for joint in settings.hardware.joints])
    with open(path, "rb") as file:
        config = tomllib.load(file)
    for record in config[SECTION]["joints"]:
        sid = record.get("servo_id")
        if sid in gains:
            record["gains"] = gains_out(gains[sid])
    tmp = path.with_suffix(path.suffix + ".tmp")
    with open(tmp, "wb") as file:
        tomli_w.dump(config, file)
    tmp.replace(path)  # atomic, as hardware/calibration.py's save


def _has_joint_records(path: Path) -> bool:
    with open(path, "rb") as file:
        return bool(tomllib.load(file).get(SECTION, {}).get("joints"))

"""Programs resource: check a G-code program on the virtual robot before anything moves,
predict its tracking error on a headless twin, run it.

Checks and dry runs run in worker processes (app/programs/workers.py), not in the
server's: the control loop keeps its ticks. At most CONCURRENT_CHECKS at a time (503
beyond, with Retry-After); a worker that dies or takes longer than
``programs.check_timeout_s`` is a 503 saying so, and the next check gets a new worker.

``POST /api/programs/check`` plans the program from where the robot is (or ``start_m``)
and runs every loop sample through the gate's checks, the joint acceleration and the
servo torque (app/programs/). Nothing moves: the answer is the report. A program that
cannot be read is a 422 naming its line and word; one that reads but fails a check is a
200 with ``ok: false`` and its violations.

``POST /api/programs/dry-run`` checks it and plays the same path on a twin of its own
(app/programs/dry_run.py), never the live robot: the predicted error per line.

``POST /api/programs/run`` checks it from where the robot is and, only when it passes,
starts a run of kind ``program`` (app/runs/: logs, stats, report, plus the error per
program line); a failing check is a 422 with the violations and nothing moves.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import replace
from typing import Any

import numpy as np
from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field, field_validator

from app.control.commands import require_motion
from app.control.errors import MotionRefused
from app.control.model import RobotModel
from app.fields import ReachVector3
from app.link.codec import plain
from app.link.paths import FEED_MAX, FEED_MIN
from app.programs.check import CheckedProgram, ProgramReport
from app.programs.dry_run import DryRunRefused
from app.programs.errors import ProgramError
from app.programs.library import MAX_NAME, LibraryError, ProgramLibrary
from app.programs.verify import Violation
from app.programs.workers import CheckJob, ProgramWorkers, WorkerError
from app.server.api.deps import (
    ControlClient,
    ControllerDep,
    ProgramWorkersDep,
    RunsDep,
    SceneDep,
    SettingsDep,
    TokenChecked,
)
from app.server.api.records import model_of
from app.server.api.responses import RunStarted
from app.server.api.runs import start_run
from app.server.errors import CONTROL, INVALID, UNAUTHORISED, ErrorBody

router = APIRouter(prefix="/programs", tags=["programs"])
# A long program's check takes seconds of CPU and up to ~1 GB (programs.max_samples loop
# samples of several arrays): it runs in a worker process (app/programs/workers.py), never
# beside the control loop in the server's; at most this many at a time, another is
# answered 503 at once (nothing is queued).
CONCURRENT_CHECKS = 2
START_TOLERANCE_M = 0.002  # as the run manager's start check


class ProgramRequest(BaseModel):
    """A program and, optionally, where it starts and its G54 origin."""

    model_config = ConfigDict(extra="forbid", strict=True)
    gcode: str = Field(description="the program's text (the subset in docs/gcode.md)")
    start_m: ReachVector3 | None = Field(
        None, description="where the tool starts [m] (default: where the robot is now)"
    )
    work_offset_m: ReachVector3 | None = Field(
        None, description="G54: the program origin in the base frame [m] (default: config)"
    )
    name: str | None = Field(
        None,
        max_length=MAX_NAME,
        description="the program's name in the library (its file's; default 'unnamed'): "
        "every program sent is kept there (GET /api/programs/library)",
    )

    @field_validator("gcode")
    @classmethod
    def _unicode(cls, gcode: str) -> str:
        """A JSON string may carry a lone surrogate (\\ud800): no UTF-8 text has one."""
        try:
            gcode.encode("utf-8")
        except UnicodeEncodeError as exc:
            raise ValueError(
                f"not Unicode text: a lone surrogate at character {exc.start + 1}"
            ) from None
        return gcode


class RunProgramRequest(ProgramRequest):
    """A program to run, as checked; feed-forward as the test runs have it."""

    feedforward: bool = Field(
        False, description="command the point runs.feedforward_lead_s ahead (servo lag)"
    )
    start_line: int | None = Field(
        None,
        ge=1,
        description="run from this line (1-based): from the first move, dwell or pause on "
        "it or after, with an approach move to its start checked like any run start "
        "(default: from the start)",
    )
    feed_override: float = Field(
        1.0,
        ge=FEED_MIN,
        le=FEED_MAX,
        description="the feed override it starts with, 0.1 to 1.0 (the program is checked "
        "at 100 % feed: never above)",
    )
    optional_stop: bool = Field(False, description="M1 stops the program (optional stop on)")


ViolationOut = model_of(
    Violation,
    "ViolationOut",
    describe={
        "line": "program line (1-based)",
        "kind": "workspace, ceiling, ik, joint_limit, joint_speed, ...; wrist_limit and "
        "wrist_speed with a wrist; run_duration (longer than a run may be: runs.max_samples; "
        "/run refuses it in the same words)",
        "message": "what, in words: the line's worst value, the limit and by how much "
        "(lengths in mm, angles in deg, rates in rad/s and rad/s^2)",
        "t_s": "first offending sample, from the program's start [s]",
        "point_m": "its point in the base frame [m]",
        "folded_under": "the index in this list of its move's first cause, under which it "
        "is folded (a consequence, or more on the same line); null: a first cause (the "
        "list is by move, each line's first cause first: docs/gcode.md)",
    },
    types={"point_m": list[float]},
)
ProgramReportOut = model_of(
    ProgramReport,
    "ProgramReportOut",
    doc="The check's report (app/programs/check.py ProgramReport).",
    describe={
        "path_m": "the path decimated for drawing [m]",
        "path_lines": "the program line of each path_m point (null where nothing moves)",
    },
    types={"violations": list[ViolationOut]},  # type: ignore[valid-type]
)


class FieldProblemOut(BaseModel):
    field: str = Field(description="the body field at fault, dotted ('start_m.1'), or 'body'")
    reason: str = Field(description="why it is refused")


class ProgramErrorOut(BaseModel):
    """Every 422 of the programs routes: a program that cannot be read (``line``, ``word``),
    one that fails its check on /run (``violations``: the check's), or a body refused before
    any program is read (``line`` and ``word`` null, ``violations``: field and reason)."""

    detail: str = Field(description="line N: WORD: reason, or field: reason")
    line: int | None = Field(
        None, description="program line (1-based); null where no line is at fault"
    )
    word: str | None = Field(
        None, description="the word at fault ('' when none is; null when no program was read)"
    )
    violations: list[ViolationOut | FieldProblemOut] = Field(  # type: ignore[valid-type]
        default_factory=list,
        description="the check's violations (/run), or each body field at fault and why",
    )


class LineErrorOut(BaseModel):
    line: int = Field(description="program line (1-based)")
    samples: int = Field(description="loop ticks spent on the line")
    rmse_m: float = Field(description="predicted sqrt(mean |goal - FK|^2) over the line [m]")
    max_m: float = Field(description="predicted largest |goal - FK| over the line [m]")


class DryRunOut(BaseModel):
    """The dry run on the headless twin (app/programs/dry_run.py DryRun)."""

    ok: bool = Field(description="the check passed")
    duration_s: float = Field(description="the path played [s]")
    lines: list[LineErrorOut] = Field(description="per program line, in execution order")
    rmse_m: list[float] = Field(description="per axis x, y, z over the path [m]")
    max_m: float = Field(description="largest |goal - FK| [m]")


NOT_READABLE: dict[int, dict[str, Any]] = {
    422: {"model": ProgramErrorOut, "description": "the program cannot be read or planned"}
}
CHECK_UNAVAILABLE: dict[int, dict[str, Any]] = {
    503: {
        "model": ErrorBody,
        "description": "the check did not come back: CONCURRENT_CHECKS (2) are running "
        "(Retry-After), its worker process died (Retry-After) or ran longer than "
        "programs.check_timeout_s; or the control loop is not running",
    }
}
REFUSED: dict[int, dict[str, Any]] = {
    422: {
        "model": ProgramErrorOut,
        "description": "the program fails its check (its violations), or cannot be read "
        "(detail, line, word); nothing moves",
    }
}


def _start(controller) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Where the robot is and its joints, as RunManager.plan picks them (None: unknown)."""
    snap = controller.snapshot()
    holding = snap.torque and not snap.estopped and not snap.faults
    point = snap.point_commanded_m if holding else snap.point_measured_m
    joints = snap.joints_commanded_rad if holding else snap.joints_measured_rad
    if not np.isfinite(point).all():
        point, joints = snap.point_measured_m, snap.joints_measured_rad
    if not np.isfinite(point).all():
        return None, None
    return point, (joints if np.isfinite(joints).all() else None)


def _start_phi(controller) -> float:
    """The wrist's angle a program starts from [rad], by the rule of :func:`_start`: the
    one commanded while the robot holds, else the one read, else the one the loop holds
    the tool at (0 without a wrist)."""
    snap = controller.snapshot()
    holding = snap.torque and not snap.estopped and not snap.faults
    for phi in (snap.phi_commanded_rad if holding else math.nan, snap.phi_measured_rad):
        if math.isfinite(phi):
            return float(phi)
    return float(snap.phi_rad)


@router.post(
    "/check",
    response_model=ProgramReportOut,
    responses={**NOT_READABLE, **UNAUTHORISED, **CHECK_UNAVAILABLE},
)
def check(
    body: ProgramRequest,
    controller: ControllerDep,
    settings: SettingsDep,
    workers: ProgramWorkersDep,
    _: TokenChecked,
    scene: SceneDep,
) -> Any:
    """Plan the program and check every loop sample (workspace with margin and ceiling,
    IK on the followed branch, joint limits, speed and acceleration, singularity margin,
    servo torque); all violations by line. Runs in a worker process; moves nothing."""
    kept = _keep(settings, body, "check")
    if isinstance(kept, JSONResponse):
        return kept
    outcome = _check(body, controller, settings, workers)
    if isinstance(outcome, JSONResponse):
        return outcome
    checked, notes = outcome
    notes = notes + kept
    report = checked.report.to_dict()
    report["notes"] = notes + report["notes"]
    if scene is not None:  # the checked path in the 3D scene, violations in red
        scene.show_program(report)
    return report


def program_error(
    detail: str, line: int | None = None, word: str | None = None, violations: list | None = None
) -> JSONResponse:
    """A 422 in the programs' error shape (ProgramErrorOut): every key present."""
    body = {"detail": detail, "line": line, "word": word, "violations": violations or []}
    return JSONResponse(body, status_code=422)


def library_of(settings) -> ProgramLibrary:
    """The program library of ``settings``: ``<runs folder>/programs/``."""
    return ProgramLibrary(settings.runs.folder_path / "programs")


def _keep(settings, body: ProgramRequest, action: str) -> list[str] | JSONResponse:
    """Keep the program sent in the library (app/programs/library.py): the notes to add
    (one when it is not kept: too long, or the folder cannot be written); the 422 naming
    ``name`` for a name the library refuses (before anything is checked)."""
    try:
        offset = None if body.work_offset_m is None else list(body.work_offset_m)
        entry = library_of(settings).add(body.gcode, body.name or "unnamed", action, offset)  # type: ignore[arg-type]
    except LibraryError as exc:
        return program_error(str(exc), violations=[{"field": exc.field, "reason": exc.reason}])
    except OSError as exc:
        return [f"not kept in the program library: {exc.strerror or exc}"]
    if entry is None:
        return ["not kept in the program library: longer than it keeps"]
    return []


def _unreadable(exc: ProgramError) -> JSONResponse:
    return program_error(str(exc), exc.line or None, exc.word)


def _unavailable(exc: WorkerError) -> JSONResponse:
    """503 for a check that did not come back: all slots busy, its worker died or ran
    too long (the message says which); Retry-After when trying again soon may work."""
    retry = {"Retry-After": "5"}  # busy, a worker died or overran: a later try may pass
    return JSONResponse({"detail": str(exc)}, status_code=503, headers=retry)


def _job(
    body: ProgramRequest, controller, settings, from_robot: bool, model: RobotModel | None = None
) -> tuple[CheckJob, list[str]]:
    """The check's inputs from ``start_m`` or where the robot is (always there with
    ``from_robot``: a run starts where the robot is), and the notes to add; the gate is
    ``model``'s (None: the robot model in use now)."""
    given = body.start_m is not None and not from_robot
    model = model or controller.model  # before where the robot is: never newer than it
    start, near = (np.asarray(body.start_m), None) if given else _start(controller)
    notes = []
    if start is None:
        if from_robot:
            raise MotionRefused("the robot's position is unknown: check the bus")
        notes.append("the robot's position is unknown: checked from programs.start_m")
    job = CheckJob(
        body.gcode,
        settings,
        gate=model.gate,
        start_m=start,
        work_offset_m=body.work_offset_m,
        near=near,
        # a run's log holds at most runs.max_samples: say so before the costly checks
        for_run=from_robot,
        start_phi_rad=_start_phi(controller),
    )
    return job, notes


def _check(
    body: ProgramRequest,
    controller,
    settings,
    workers: ProgramWorkers,
    from_robot: bool = False,
    model: RobotModel | None = None,
) -> tuple[CheckedProgram, list[str]] | JSONResponse:
    """The check in a worker process (blocks this thread until it answers), against
    ``model`` (None: the one in use); the 422 of an unreadable program, the 503 of a check
    that did not come back."""
    job, notes = _job(body, controller, settings, from_robot, model)
    try:
        return workers.check(job), notes
    except ProgramError as exc:
        return _unreadable(exc)
    except WorkerError as exc:
        return _unavailable(exc)


def _require_motion(controller) -> None:
    """MotionRefused (409) when the robot may not move now, in the loop's own words (the
    published snapshot has the loop state's torque, estopped and faults)."""
    require_motion(controller.snapshot())  # type: ignore[arg-type]


def _refused(checked: CheckedProgram) -> JSONResponse:
    violations = checked.report.to_dict()["violations"]
    first = violations[0]  # by move (fold): the first bad line's first cause
    detail = (
        f"line {first['line']}: {first['kind']}: {first['message']} "
        f"({len(violations)} violation(s); the program was not run)"
    )
    return program_error(detail, first["line"], None, violations)


class ProgramDefaultsOut(BaseModel):
    """What a program is checked with when the body leaves it out (the config's)."""

    work_offset_m: list[float] = Field(description="G54: the program origin [m]")
    start_m: list[float] = Field(description="where an offline check starts [m]")
    dry_run_max_s: float = Field(description="longest program the dry run plays [s]")
    loop_rate_hz: float = Field(description="the loop's rate: one check sample per period")


@router.get("/defaults", response_model=ProgramDefaultsOut, responses={**UNAUTHORISED, **INVALID})
def program_defaults(settings: SettingsDep, _: TokenChecked) -> Any:
    """The config's work offset, offline start and dry-run limit (the page's defaults)."""
    return {
        "work_offset_m": list(settings.programs.work_offset_m),
        "start_m": list(settings.programs.start_m),
        "dry_run_max_s": settings.programs.dry_run_max_s,
        "loop_rate_hz": settings.loop.rate_hz,
    }


class LibraryEntryOut(BaseModel):
    """A program kept in the library (app/programs/library.py Entry)."""

    id: str = Field(description="16 hex digits (of the text's SHA-256): the same text is one")
    name: str = Field(description="the name it was last sent with")
    bytes: int = Field(description="its size in UTF-8 [bytes]")
    lines: int = Field(description="its lines")
    first: str = Field(description="its first non-empty line (up to 80 characters)")
    sent_at: float = Field(description="the last send [s since the epoch, UTC]")
    action: str = Field(description="the last send's: check, dry-run or run")
    sends: int = Field(description="how many times it was sent")
    work_offset_m: list[float] | None = Field(
        description="the G54 origin it was last sent with [m] (null: the config's)"
    )


class LibraryOut(BaseModel):
    """The programs kept, the most recently sent first."""

    programs: list[LibraryEntryOut]
    max_entries: int = Field(description="the most kept (the least recently sent go first)")
    max_bytes: int = Field(description="a longer program is not kept [bytes]")


class LibraryProgramOut(LibraryEntryOut):
    """A kept program with its text."""

    gcode: str = Field(description="the program's text")


@router.get("/library", response_model=LibraryOut, responses={**UNAUTHORISED, **INVALID})
def list_library(settings: SettingsDep, _: TokenChecked) -> Any:
    """Every program sent to check, dry-run or run (any client), the most recent first."""
    library = library_of(settings)
    entries = library.entries()
    return {
        "programs": [e.to_dict() for e in entries],
        "max_entries": library.max_entries,
        "max_bytes": library.max_bytes,
    }


@router.get(
    "/library/{program_id}",
    response_model=LibraryProgramOut,
    responses={
        **UNAUTHORISED,
        404: {"model": ErrorBody, "description": "no program of that id is kept"},
        422: {"model": ProgramErrorOut, "description": "not an id of the library's form"},
    },
)
def get_library_program(program_id: str, settings: SettingsDep, _: TokenChecked) -> Any:
    """A kept program and its text, by its id from the list (16 hex digits: nothing else
    is read, so no path leaves the library's folder)."""
    try:
        entry, text = library_of(settings).get(program_id)
    except LibraryError as exc:
        return program_error(str(exc), violations=[{"field": exc.field, "reason": exc.reason}])
    except (KeyError, OSError, UnicodeDecodeError):
        return JSONResponse(
            {"detail": f"id: no program {program_id} in the library"}, status_code=404
        )
    return {**entry.to_dict(), "gcode": text}


@router.post(
    "/dry-run",
    response_model=DryRunOut,
    responses={**NOT_READABLE, **UNAUTHORISED, **CHECK_UNAVAILABLE},
)
def dry_run_program(
    body: RunProgramRequest,
    controller: ControllerDep,
    settings: SettingsDep,
    workers: ProgramWorkersDep,
    _: TokenChecked,
) -> Any:
    """Check the program, then play its timed path on a headless twin of the robot (a
    simulated bus of its own, stepped offline; never the live robot): the predicted
    tracking error (goal - FK) per program line. Programs longer than
    programs.dry_run_max_s are refused (422). Both in a worker process; moves nothing."""
    kept = _keep(settings, body, "dry-run")
    if isinstance(kept, JSONResponse):
        return kept
    job, _notes = _job(body, controller, settings, from_robot=False)
    try:
        _checked, result = workers.dry_run(job, body.feedforward)
    except ProgramError as exc:
        return _unreadable(exc)
    except DryRunRefused as exc:
        return program_error(str(exc))
    except WorkerError as exc:
        return _unavailable(exc)
    return result.to_dict()


@router.post(
    "/run", response_model=RunStarted, responses={**CONTROL, **REFUSED, **CHECK_UNAVAILABLE}
)
async def run_program(
    request: Request,
    body: RunProgramRequest,
    runs: RunsDep,
    workers: ProgramWorkersDep,
    _: ControlClient,
) -> Any:
    """Check the program from where the robot is (a run starts there: a start_m more than
    2 mm away is a 422) and, only if it passes, run it as a run of kind "program";
    422 with the violations (detail names the first) when it fails, and nothing moves.
    Its progress carries program_line; its stats program.lines, the error per line."""
    controller = runs.controller
    kept = _keep(controller.settings, body, "run")
    if isinstance(kept, JSONResponse):
        return kept
    _require_motion(controller)  # torque off, e-stop, fault: said as such, before the check
    controller.owner.check()  # a calibration or tuning holds the robot: before the check too
    model = controller.model  # the run is refused if another is in use when it starts
    checked = await asyncio.to_thread(
        _check, body, controller, controller.settings, workers, True, model
    )
    if isinstance(checked, JSONResponse):
        return checked
    program = checked[0]
    report = program.report
    if not program.path.segments:  # empty, or comments only: a run of it would be nothing
        return program_error("gcode: the program has no move or dwell: nothing to run")
    # the check took time: the path starts where the robot was then; if it has moved since,
    # the run would add an approach the report never showed. Check again from where it is.
    now, _ = _start(controller)
    moved = np.inf if now is None else float(np.linalg.norm(now - np.asarray(report.start_m)))
    if moved > START_TOLERANCE_M:
        raise MotionRefused(
            f"the robot moved {moved * 1e3:.1f} mm while the program was checked: "
            "it runs only from where it was checked; check and run again"
        )
    if body.start_m is not None:  # a run starts where the robot is: say so, never ignore it
        distance = float(np.linalg.norm(np.asarray(body.start_m) - report.start_m))
        if distance > START_TOLERANCE_M:
            where = ", ".join(f"{v * 1e3:.1f}" for v in report.start_m)
            return program_error(
                f"start_m: a program runs from where the robot is, ({where}) mm, "
                f"{distance * 1e3:.1f} mm from start_m; leave start_m out or move there"
            )
    if not report.ok:
        return _refused(program)
    record = {
        "gcode": body.gcode,
        "lines": report.lines,
        "segments": report.segments,
        "duration_s": report.duration_s,
        "length_m": report.length_m,
        "start_m": report.start_m,
        "work_offset_m": report.work_offset_m,
        "feedforward": body.feedforward,
    }
    path = replace(
        program.path,
        feedforward=body.feedforward,
        feed_override=body.feed_override,
        optional_stop=body.optional_stop,
    )
    if body.start_line is not None:
        if body.start_line > report.lines:
            return program_error(
                f"start_line: line {body.start_line} is past the program's end "
                f"({report.lines} lines)"
            )
        if path.moves_wrist:  # its approach would not turn the wrist to that line's phi
            return program_error(
                "start_line: a program that turns the wrist (A words) runs from its start only"
            )
        try:
            path = path.from_line(body.start_line)
        except ValueError as exc:
            return program_error(str(exc))
        record["start_line"] = body.start_line
    record["feed_override"] = body.feed_override
    record["optional_stop"] = body.optional_stop
    return await start_run(request, runs, path, "program", record, model)


class FeedOverrideRequest(BaseModel):
    """A feed override for the running program."""

    model_config = ConfigDict(extra="forbid", strict=True)
    override: float = Field(
        ge=FEED_MIN,
        le=FEED_MAX,
        description="0.1 to 1.0 of the planned feed (checked at 100 %: never above)",
    )


class OptionalStopRequest(BaseModel):
    """The optional stop switch: M1 stops the program while it is on."""

    model_config = ConfigDict(extra="forbid", strict=True)
    on: bool = Field(description="M1 stops the program")


class ProgramPlayOut(BaseModel):
    """Where the running program's time stands after a command."""

    run_id: str
    feed_override: float = Field(description="the feed override set, 0.1 to 1.0")
    feed_rate: float = Field(description="the rate its time runs at now (0: standing)")
    paused: str | None = Field(description="why it stands or is stopping; null: running")
    time_left_s: float = Field(description="path time left at the feed override [s]")
    optional_stop: bool = Field(description="M1 stops")
    stop_line: int | None = Field(description="the line a step or M0 / M1 stops (stopped) at")


STEER_REFUSED: dict[int, dict[str, Any]] = {
    **CONTROL,
    409: {
        "model": ErrorBody,
        "description": "no program is running, a step with no line end ahead, no lease, "
        "or a calibration or tuning holds the robot; nothing changes",
    },
    422: {
        "model": ProgramErrorOut,
        "description": "the body is refused (violations name the field and the reason)",
    },
}


async def _steer(runs, action: str, **values: Any) -> dict[str, Any]:
    run, state = await asyncio.to_thread(runs.steer, action, **values)
    feed = state if isinstance(state, dict) else plain(state)
    return {
        "run_id": run.run_id,
        "feed_override": feed["override"],
        "feed_rate": feed["rate"],
        "paused": feed["paused"],
        "time_left_s": feed["time_left_s"],
        "optional_stop": feed["optional_stop"],
        "stop_line": feed["stop_line"],
    }


@router.post("/pause", response_model=ProgramPlayOut, responses=STEER_REFUSED)
async def pause_program(runs: RunsDep, _: ControlClient) -> Any:
    """Pause the running program: its time slows to a stand at a bounded rate, so the
    tool decelerates along the checked path and stays on it (409 when none runs)."""
    return await _steer(runs, "pause")


@router.post("/resume", response_model=ProgramPlayOut, responses=STEER_REFUSED)
async def resume_program(runs: RunsDep, _: ControlClient) -> Any:
    """Resume a paused (or M0 / M1 / step-stopped) program at its feed override."""
    return await _steer(runs, "resume")


@router.post("/step", response_model=ProgramPlayOut, responses=STEER_REFUSED)
async def step_program(runs: RunsDep, _: ControlClient) -> Any:
    """Single step: run to the end of the current line (the next one it can stop at
    exactly when already braking past it) and stop there; Resume goes on."""
    return await _steer(runs, "step")


@router.put("/feed", response_model=ProgramPlayOut, responses=STEER_REFUSED)
async def set_feed(body: FeedOverrideRequest, runs: RunsDep, _: ControlClient) -> Any:
    """Set the running program's feed override (0.1 to 1.0; the program was checked at
    100 %: never above); its time rate moves there at a bounded slew."""
    return await _steer(runs, "feed", override=body.override)


@router.put("/optional-stop", response_model=ProgramPlayOut, responses=STEER_REFUSED)
async def set_optional_stop(body: OptionalStopRequest, runs: RunsDep, _: ControlClient) -> Any:
    """Switch the optional stop of the running program: M1 stops it while on."""
    return await _steer(runs, "optional_stop", on=body.on)

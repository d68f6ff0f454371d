"""Runs resource: start the thesis's sinusoid test, list runs, their stats and files."""

from __future__ import annotations

import asyncio
import logging
import math
import time
from itertools import pairwise
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse
from pydantic import BaseModel, ConfigDict, Field, model_validator

from app.control.errors import GoalRejected, MotionRefused
from app.control.model import RobotModel
from app.runs.describe import describe
from app.runs.logs import MEDIA_TYPE as MCAP_MEDIA_TYPE
from app.runs.logs import read_messages
from app.runs.manager import Run, RunManager
from app.runs.paths import ChirpParams, StepParams, WaypointParams
from app.runs.stats import error_stats, window_mask
from app.runs.trajectories import SinusoidParams, TimedPath
from app.server.api.deps import ControlClient, RunsDep
from app.server.api.models import ReachVector3, Vector3
from app.server.api.responses import RunOut, RunStarted, WindowStats
from app.server.errors import CONTROL, INVALID, NOT_FOUND, PlanningTimeout

log = logging.getLogger(__name__)
router = APIRouter(tags=["runs"])
_DEFAULT = SinusoidParams()
MAX_WAYPOINTS = 1000
FILES = {  # a run's files and their media types
    "log.mcap": MCAP_MEDIA_TYPE,
    "log.cut.mcap": MCAP_MEDIA_TYPE,  # an interrupted run's log as the crash left it
    "log.csv": "text/csv",
    "report.png": "image/png",
    "report.pdf": "application/pdf",
}


Seconds = Annotated[float, Field(gt=0, le=600, allow_inf_nan=False, strict=True)]
Axis = Annotated[int, Field(ge=0, le=2, strict=True, description="0 = x, 1 = y, 2 = z")]

HzOrZero = Annotated[float, Field(ge=0, le=20, allow_inf_nan=False, strict=True)]
Hz = Annotated[float, Field(gt=0, le=20, allow_inf_nan=False, strict=True)]


class _RunBody(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class SinusoidRequest(_RunBody):
    """Per-axis sinusoid; every field optional, defaults are the thesis test (ch. 6.1)."""

    amplitude_m: ReachVector3 = list(_DEFAULT.amplitude_m)
    frequency_hz: Annotated[list[HzOrZero], Field(min_length=3, max_length=3)] = list(
        _DEFAULT.frequency_hz
    )
    phase_rad: Vector3 = list(_DEFAULT.phase_rad)
    offset_m: ReachVector3 = list(_DEFAULT.offset_m)
    duration_s: Seconds = _DEFAULT.duration_s
    feedforward: bool = False
    phi_amplitude_rad: Annotated[float, Field(ge=0, le=math.pi, allow_inf_nan=False)] = Field(
        0.0, description="with a [wrist]: phi(t) = A sin(2 pi f t) [rad]; 0 leaves it alone"
    )
    phi_frequency_hz: HzOrZero = Field(0.0, description="the wrist's frequency f [Hz]")

    def params(self) -> SinusoidParams:
        return SinusoidParams(
            tuple(self.amplitude_m),
            tuple(self.frequency_hz),
            tuple(self.phase_rad),
            tuple(self.offset_m),
            self.duration_s,
            self.feedforward,
            self.phi_amplitude_rad,
            self.phi_frequency_hz,
        )  # type: ignore[arg-type]


class ChirpRequest(_RunBody):
    """Linear frequency sweep on one axis, for identifying the servo response."""

    axis: Axis = 2
    amplitude_m: Annotated[float, Field(gt=0, le=0.2, allow_inf_nan=False, strict=True)] = 0.02
    f0_hz: Hz = 0.2
    f1_hz: Hz = 3.0
    offset_m: ReachVector3 = list(_DEFAULT.offset_m)
    duration_s: Seconds = 10.0
    feedforward: bool = False

    def params(self) -> ChirpParams:
        return ChirpParams(**{**self.model_dump(), "offset_m": tuple(self.offset_m)})


class StepRequest(_RunBody):
    """A position step on one axis (servo step response), within the run."""

    axis: Axis = 2
    size_m: Annotated[float, Field(ge=-0.05, le=0.05, allow_inf_nan=False, strict=True)] = 0.005
    step_at_s: Annotated[float, Field(ge=0, le=60, allow_inf_nan=False, strict=True)] = 0.5
    offset_m: ReachVector3 = list(_DEFAULT.offset_m)
    duration_s: Seconds = 2.0
    phi_step_rad: Annotated[float, Field(ge=-math.pi, le=math.pi, allow_inf_nan=False)] = Field(
        0.0, description="with a [wrist]: a step of phi [rad] at step_at_s too; 0 leaves it alone"
    )

    @model_validator(mode="after")
    def _step_inside(self) -> StepRequest:
        if self.step_at_s >= self.duration_s:
            raise ValueError(
                f"step_at_s: {self.step_at_s:g} s is not before the run's end "
                f"(duration_s = {self.duration_s:g} s)"
            )
        return self

    def params(self) -> StepParams:
        return StepParams(**{**self.model_dump(), "offset_m": tuple(self.offset_m)})


class WaypointsRequest(_RunBody):
    """Points [m] reached at times [s] (first at 0), resting at each; minimum-jerk between."""

    points_m: Annotated[list[ReachVector3], Field(min_length=2, max_length=MAX_WAYPOINTS)]
    times_s: Annotated[
        list[Annotated[float, Field(ge=0, le=600, allow_inf_nan=False, strict=True)]],
        Field(min_length=2, max_length=MAX_WAYPOINTS),
    ]
    feedforward: bool = False

    @model_validator(mode="after")
    def _timed(self) -> WaypointsRequest:
        if len(self.times_s) != len(self.points_m):
            raise ValueError(
                f"times_s: one time per point ({len(self.times_s)} times, "
                f"{len(self.points_m)} points)"
            )
        if self.times_s[0] != 0.0 or not all(b > a for a, b in pairwise(self.times_s)):
            raise ValueError("times_s: must start at 0 and increase")
        return self

    def params(self) -> WaypointParams:
        points = tuple(tuple(p) for p in self.points_m)
        try:
            return WaypointParams(points, tuple(self.times_s), self.feedforward)  # type: ignore[arg-type]
        except ValueError as exc:  # counts and order the schema cannot say
            raise GoalRejected(str(exc)) from exc


def _run(runs: RunManager, run_id: str) -> Run:
    run = runs.get(run_id)
    if run is None:
        raise HTTPException(404, f"no run {run_id!r}")
    return run


async def start_run(
    request: Request,
    runs: RunManager,
    params: TimedPath,
    kind: str,
    record: dict[str, Any] | None = None,
    model: RobotModel | None = None,
) -> dict:
    """Plan and check in a worker thread (other requests go on meanwhile), then start only
    if the answer can still reach the caller: in time, and to a client still connected.
    ``record``: the parameters saved in run.json (default: ``params``' fields); ``model``:
    the robot model a check before this one used (None: the one in use now)."""
    began = time.monotonic()
    prepared = await asyncio.to_thread(runs.prepare, params, kind, record, model)
    took_s, limit_s = time.monotonic() - began, runs.controller.settings.runs.plan_timeout_s
    if took_s > limit_s:
        raise PlanningTimeout(
            f"planning took {took_s:.1f} s, over the limit of {limit_s:g} s "
            "(runs.plan_timeout_s): the run was not started; try a shorter run"
        )
    if await request.is_disconnected():
        log.warning("%s run planned for a client that has gone: not started", kind)
        raise MotionRefused("the client disconnected while the run was planned: not started")
    run = await asyncio.to_thread(runs.launch, prepared)
    return {"run_id": run.run_id}


@router.post("/tests/sinusoid", response_model=RunStarted, responses=CONTROL)
async def start_sinusoid(request: Request, body: SinusoidRequest, runs: RunsDep, _: ControlClient):
    """Check the whole path, then run it; 422 names the first infeasible time and point."""
    return await start_run(request, runs, body.params(), "sinusoid")


@router.post("/tests/chirp", response_model=RunStarted, responses=CONTROL)
async def start_chirp(request: Request, body: ChirpRequest, runs: RunsDep, _: ControlClient):
    """A frequency sweep f0 -> f1 on one axis; checked like the sinusoid."""
    return await start_run(request, runs, body.params(), "chirp")


@router.post("/tests/step", response_model=RunStarted, responses=CONTROL)
async def start_step(request: Request, body: StepRequest, runs: RunsDep, _: ControlClient):
    """A step on one axis; small steps pass the joint-speed limit unchanged."""
    return await start_run(request, runs, body.params(), "step")


@router.post("/tests/waypoints", response_model=RunStarted, responses=CONTROL)
async def start_waypoints(
    request: Request, body: WaypointsRequest, runs: RunsDep, _: ControlClient
):
    """Timed waypoints (pick-and-place, raster); checked like the sinusoid."""
    return await start_run(request, runs, body.params(), "waypoints")


def run_out(runs: RunManager, run: Run) -> dict[str, Any]:
    """A run's record for the API (RunOut): run.json's fields, its test in words and, while
    it goes, its progress."""
    out = run.as_dict()
    out["description"] = describe(run.kind, run.params, run.conditions)
    out["progress"] = runs.progress(run.run_id)
    return out


@router.get("/runs", response_model=list[RunOut])
def list_runs(runs: RunsDep) -> list[dict[str, Any]]:
    """All runs, newest first, with state and stats; the running one with its progress."""
    return [run_out(runs, run) for run in runs.list()]


@router.get("/runs/{run_id}", response_model=RunOut, responses={**NOT_FOUND, **INVALID})
def get_run(run_id: str, runs: RunsDep) -> dict[str, Any]:
    """One run: state, parameters, conditions, stats.tracking.{x,y,z}.{mean_m, rmse_m, ...}."""
    return run_out(runs, _run(runs, run_id))


@router.post("/runs/{run_id}/abort", response_model=RunOut, responses={**CONTROL, **NOT_FOUND})
async def abort_run(run_id: str, runs: RunsDep, _: ControlClient) -> dict[str, Any]:
    """Stop a running run; the robot holds where it is and the log stays readable."""
    run = _run(runs, run_id)
    await asyncio.to_thread(runs.abort, run_id)
    return run_out(runs, run)


@router.get("/runs/{run_id}/stats", response_model=WindowStats, responses={**NOT_FOUND, **INVALID})
def window_stats(
    run_id: str, runs: RunsDep, start_s: float | None = None, end_s: float | None = None
) -> dict[str, Any]:
    """Tracking stats recomputed over [start_s, end_s] of run time (any phase), from the log."""
    run = _run(runs, run_id)
    rows = read_messages(run.folder / "log.mcap")
    if not rows:
        raise HTTPException(404, "the run has no samples")
    times = np.array([r["t_s"] for r in rows])
    goal, measured = (
        np.array([[r[f"{kind}_{a}_m"] for a in "xyz"] for r in rows], dtype=float)
        for kind in ("goal", "measured")
    )
    return {
        "tracking": error_stats(goal, measured, window_mask(times, start_s, end_s)),
        "start_s": start_s,
        "end_s": end_s,
    }


@router.get(
    "/runs/{run_id}/{name}",
    response_class=FileResponse,
    responses={200: {"content": {t: {} for t in set(FILES.values())}}, **NOT_FOUND, **INVALID},
)
def run_file(run_id: str, name: str, runs: RunsDep) -> FileResponse:
    """log.mcap, log.csv (written as the run goes), report.png and report.pdf (when it has
    ended), log.cut.mcap (an interrupted run's log as the crash left it). Served inline
    with the file's media type (a browser shows the report, a download keeps the name);
    HEAD answers the same headers without the body."""
    if name not in FILES:
        raise HTTPException(404, f"no file {name!r}; files are {', '.join(FILES)}")
    path = _run(runs, run_id).folder / name
    if not path.exists():
        raise HTTPException(404, f"{name} is not written yet")
    return FileResponse(
        path,
        media_type=FILES[name],
        filename=f"{run_id}-{name}",
        content_disposition_type="inline",
    )


# HEAD on a file: the same answer without its body (not a second operation in the schema)
router.add_api_route("/runs/{run_id}/{name}", run_file, methods=["HEAD"], include_in_schema=False)

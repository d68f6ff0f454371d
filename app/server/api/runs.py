"""Runs resource: start test runs (a route per run type of app/runs/types.py: the thesis's
sinusoid, a chirp, a step, waypoints), list runs, their stats and files."""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any

import numpy as np
from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse

from app.control.errors import MotionRefused
from app.control.model import RobotModel
from app.runs.describe import describe
from app.runs.logs import MEDIA_TYPE as MCAP_MEDIA_TYPE
from app.runs.logs import read_messages
from app.runs.manager import Run, RunManager
from app.runs.stats import error_stats, window_mask
from app.runs.trajectories import TimedPath
from app.runs.types import RUN_TYPES, RunRequest, RunType
from app.runs.types import ChirpRequest as ChirpRequest  # the bodies, importable here too
from app.runs.types import SinusoidRequest as SinusoidRequest
from app.runs.types import StepRequest as StepRequest
from app.runs.types import WaypointsRequest as WaypointsRequest
from app.server.api.deps import ControlClient, RunsDep
from app.server.api.responses import RunOut, RunStarted, WindowStats
from app.server.errors import CONTROL, INVALID, NOT_FOUND, PlanningTimeout

log = logging.getLogger(__name__)
router = APIRouter(tags=["runs"])
FILES = {  # a run's files and their media types
    "log.mcap": MCAP_MEDIA_TYPE,
    "log.cut.mcap": MCAP_MEDIA_TYPE,  # an interrupted run's log as the crash left it
    "log.ros2.mcap": MCAP_MEDIA_TYPE,  # the run as ROS 2 messages (docs/ros2.md)
    "log.ros2.cut.mcap": MCAP_MEDIA_TYPE,
    "log.csv": "text/csv",
    "report.png": "image/png",
    "report.pdf": "application/pdf",
}


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


def _starter(run_type: RunType) -> Callable[..., Awaitable[dict]]:
    """The route starting a run of ``run_type``: its body is the type's request model."""

    async def start(request: Request, body: RunRequest, runs: RunsDep, _: ControlClient):
        return await start_run(request, runs, body.params(), run_type.name)

    start.__annotations__ = {**start.__annotations__, "body": run_type.request}
    start.__name__ = start.__qualname__ = f"start_{run_type.name}"
    start.__doc__ = run_type.doc
    return start


for _type in RUN_TYPES.values():  # POST /tests/sinusoid, /tests/chirp, ...
    router.add_api_route(
        f"/tests/{_type.name}",
        _starter(_type),
        methods=["POST"],
        response_model=RunStarted,
        responses=CONTROL,
    )


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

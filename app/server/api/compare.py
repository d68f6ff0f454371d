"""Reading runs back: two or more runs' statistics side by side and their errors
overlaid; one run's recorded signals, decimated, for replay in the page's plots.

Its paths sit under /api/runs/, so this router is included before the runs router (whose
/runs/{run_id} would otherwise take "compare" for a run id, and /runs/{run_id}/{name}
"series" for a file name).
"""

from __future__ import annotations

from typing import Annotated, Any
from urllib.parse import quote

from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field

from app.runs import compare
from app.runs import series as run_series
from app.runs.logs import read_messages
from app.runs.manager import Run, RunManager
from app.server.api.deps import RunsDep, SettingsDep
from app.server.api.responses import CompareOut
from app.server.api.runs import run_out
from app.server.errors import CONFLICT, INVALID, NOT_FOUND

router = APIRouter(tags=["runs"])
Ids = Annotated[
    str,
    Query(
        min_length=1,
        max_length=compare.MAX_RUNS * 64,
        description=f"{compare.MIN_RUNS} to {compare.MAX_RUNS} run ids, comma-separated",
    ),
]
ERRORS = {**NOT_FOUND, **CONFLICT, **INVALID}


def _runs(runs: RunManager, ids: str) -> list[Run]:
    """The runs asked for, in order: 422 for too few or too many ids, 404 naming every
    unknown id, 409 for a run that is still going (nothing to compare yet)."""
    try:
        wanted = compare.parse_ids(ids)
    except compare.CompareError as exc:
        raise HTTPException(422, str(exc)) from None
    unknown = [run_id for run_id in wanted if runs.get(run_id) is None]
    if unknown:
        raise HTTPException(404, "no run " + ", ".join(repr(i) for i in unknown))
    found = [runs.get(run_id) for run_id in wanted]
    running = [run.run_id for run in found if run is not None and run.state == "running"]
    if running:
        raise HTTPException(409, f"run {running[0]} is still running: compare it when it ends")
    return [run for run in found if run is not None]


@router.get("/runs/compare", response_model=CompareOut, responses=ERRORS)
def compare_runs(ids: Ids, runs: RunsDep) -> dict[str, Any]:
    """Runs side by side: their records, one table row per figure (test, state, verdict,
    loop figures, per-axis RMSE, max |e|, mean [mm] and share under 1 mm [%]), and the
    address of the overlaid error plot."""
    found = _runs(runs, ids)
    records = [run_out(runs, run) for run in found]
    ids_text = ",".join(run.run_id for run in found)
    return {
        "ids": [run.run_id for run in found],
        "runs": records,
        "rows": compare.table(records),
        "plot": f"/api/runs/compare.png?ids={quote(ids_text)}",
    }


@router.get(
    "/runs/compare.png",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}}, **ERRORS},
)
def compare_plot(ids: Ids, runs: RunsDep, settings: SettingsDep) -> Response:
    """Each run's error per axis over its scored part, overlaid (time from the start of
    the scored part) [mm]; a PNG."""
    found = _runs(runs, ids)
    records = [run.as_dict() for run in found]
    image = compare.png(records, [run.folder for run in found], settings.runs.stats_skip_s)
    return Response(image, media_type="image/png")


class SeriesOut(BaseModel):
    """A run's recorded signals, every ``stride``-th tick of its log (SI: m, rad, s)."""

    model_config = ConfigDict(extra="forbid")
    run_id: str
    kind: str
    state: str
    samples: int = Field(description="ticks in the log")
    stride: int = Field(description="every how many ticks one is given")
    t_s: list[float] = Field(description="run time of each given tick [s]")
    phase: list[str] = Field(description="the run's phase at each given tick")
    signals: dict[str, list[float | None]] = Field(
        description="log column (logs.COLUMNS name, e.g. goal_x_m, measured_q1_rad) -> its "
        "values at t_s, null where unknown; error_{x,y,z}_m = goal - measured, and in a hold "
        "world_error_{x,y,z}_m; columns the run never filled are left out"
    )


MaxPoints = Annotated[
    int,
    Query(
        ge=10,
        le=run_series.MAX_POINTS,
        description=f"at most this many ticks per signal (10-{run_series.MAX_POINTS}); "
        "a longer run is decimated (every n-th tick)",
    ),
]


@router.get("/runs/{run_id}/series", response_model=SeriesOut, responses={**NOT_FOUND, **INVALID})
def recorded_series(
    run_id: str, runs: RunsDep, max_points: MaxPoints = run_series.DEFAULT_POINTS
) -> dict[str, Any]:
    """A run's recorded signals for replay: goal, measured and error per axis, the joints
    (commanded and measured), the world frame in a hold, the wrist; every n-th tick so that
    at most ``max_points`` come (404 for an unknown run or one without a log)."""
    run = runs.get(run_id)
    if run is None:
        raise HTTPException(404, f"no run {run_id!r}")
    path = run.folder / "log.mcap"
    if not path.exists():
        raise HTTPException(404, f"run {run_id} has no log")
    try:
        rows = read_messages(path)
    except (OSError, ValueError) as exc:
        raise HTTPException(404, f"run {run_id}'s log cannot be read: {exc}") from None
    out = run_series.series(rows, max_points)
    return {"run_id": run.run_id, "kind": run.kind, "state": run.state, **out}

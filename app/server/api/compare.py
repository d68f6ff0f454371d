"""Compare runs: two or more runs' statistics side by side and their errors overlaid.

Its paths sit under /api/runs/, so this router is included before the runs router (whose
/runs/{run_id} would otherwise take "compare" for a run id).
"""

from __future__ import annotations

from typing import Annotated, Any
from urllib.parse import quote

from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import Response

from app.runs import compare
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

"""What the dashboard page (static/) needs beyond the robot and runs resources.

- ``GET /api/info``: static facts the page cannot read from status (viser port, whether a
  token is required, the jog and speed limits it shows next to its controls).
- ``GET /api/tests``: the run types (app/runs/types.py ``RUN_TYPES``) with their start and
  check paths and their bodies' JSON schemas (fields, SI units in the names, bounds,
  defaults): the page's test-run form is made from it, so a new run type needs no page code.
- ``POST /api/tests/<name>/check``, one per run type: the same planning and whole-path
  check as starting a run, without moving, plus the peak joint speed, for the form's
  preview.
- ``GET /vendor/plotly.min.js``: plotly.js as shipped inside the ``plotly`` Python package,
  so the page's plots work offline and the file comes from the install, not from the repo.

Paths are absolute here (the router is included without a prefix) because the vendor file
lives outside /api.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import numpy as np
import plotly
from fastapi import APIRouter, Depends, HTTPException
from fastapi.responses import FileResponse
from pydantic import BaseModel, ConfigDict, Field

from app.control.controller import Controller
from app.control.errors import GoalRejected, MotionRefused
from app.runs.manager import RunManager
from app.runs.paths import StepParams
from app.runs.trajectories import TimedPath
from app.runs.types import RUN_TYPES, RunRequest, RunType
from app.scene import Scene
from app.server.api.deps import (
    ControllerDep,
    EstopPortDep,
    RunsDep,
    SceneDep,
    SettingsDep,
    TokenChecked,
    require_read_token,
)
from app.server.api.responses import InfoOut
from app.server.errors import INVALID, UNAUTHORISED, UNAVAILABLE

router = APIRouter(tags=["dashboard"])
PLOTLY_JS = Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"


class RunCheck(BaseModel):
    """Preview of a test run: would it start, and how hard it drives the joints (the peak
    joint speed: null where no sample has a joint solution, or for a step, whose jump is
    the servo's to make, not the path's)."""

    feasible: bool
    detail: str | None = None
    peak_joint_speed_rad_s: float | None = None
    joint_speed_limit_rad_s: float
    peak_speed_m_s: float
    peak_acceleration_m_s2: float


SinusoidCheck = RunCheck  # the sinusoid's preview, its first


class RunTypeOut(BaseModel):
    """A run type the API starts: ``name`` (the run's kind), ``doc`` (what it is),
    ``start`` and ``check`` (the paths to POST its body to) and ``schema`` (the body's JSON
    schema: each field's type, bounds and default; a field's unit is its name's suffix,
    _m metres, _rad radians, _hz hertz, _s seconds)."""

    name: str
    doc: str
    start: str
    check: str
    schema_: dict[str, Any] = Field(alias="schema")

    model_config = ConfigDict(populate_by_name=True)


def _viser_port(scene: Scene | None) -> int | None:
    """The port viser is bound to (port 0 in the config means a free one), None if no scene."""
    if scene is None:
        return None
    server = getattr(scene, "server", None)
    return server.get_port() if server is not None else scene.port


def node_host(robot: str) -> str | None:
    """The host of a robot node elsewhere (``link.robot`` an endpoint, e.g.
    tcp/192.168.1.20:7447 -> 192.168.1.20): where the page reaches its e-stop listener;
    None where the node runs on the station's machine (the page's own host)."""
    if robot in ("embedded", "in-process") or "/" not in robot:
        return None
    host = robot.split("/", 1)[1].rsplit(":", 1)[0].strip("[]")
    return None if host in ("127.0.0.1", "localhost", "::1") else host


@router.get("/api/info", response_model=InfoOut)
def get_info(
    settings: SettingsDep, scene: SceneDep, estop_port: EstopPortDep, controller: ControllerDep
) -> dict[str, Any]:
    """Viser and e-stop ports, token requirement and the limits the page shows beside its
    controls; the tool offset and the wrist (the page shows phi only with one); the robot
    model in use."""
    wrist = settings.wrist
    return {
        "viser_port": _viser_port(scene),
        "estop_port": estop_port,
        "estop_host": node_host(settings.link.robot),
        "token_required": settings.server.token is not None,
        "telemetry_hz": settings.server.telemetry_hz,
        "jog_max_velocity_m_s": settings.jog.max_velocity_m_s,
        "jog_step_m": settings.jog.step_m,
        "confirm_move_m": settings.jog.confirm_move_m,
        "home_m": list(settings.jog.home_m),
        "joint_speed_limit_rad_s": settings.limits.joint_speed_rad_s,
        "loop_rate_hz": settings.loop.rate_hz,
        "tool_offset_m": list(settings.tool.offset_m),
        "wrist": {
            "enabled": wrist.enabled,
            "min_rad": wrist.min_angle_rad if wrist.enabled else None,
            "max_rad": wrist.max_angle_rad if wrist.enabled else None,
        },
        "robot": controller.model.describe(),
    }


def peak_joint_speed(controller: Controller, params: TimedPath) -> float | None:
    """Largest joint speed [rad/s] over the timed path ``params``, on the working IK branch.

    Sampled at the loop period like the feasibility check; None when no sample has a joint
    solution (the check then names why). Not ``near`` the current joints: from a far pose
    (a relaxed arm) that picked other branches for some samples, and jumps between them
    read as hundreds of rad/s.
    """
    times = np.arange(0.0, params.duration_s, controller.period_s)
    gate = controller.gate  # read once: its robot is the one it checks
    platform = gate.platform(params.derivatives(times, 0))  # a tip's path
    joints, ok = gate.robot.ik(platform)
    if times.size < 2 or not ok.any():
        return None
    speed = np.abs(np.diff(joints, axis=0)) / controller.period_s
    return float(np.nanmax(speed)) if np.isfinite(speed).any() else None


def check_run(runs: RunManager, controller: Controller, params: TimedPath) -> dict:
    """The preview of a run of ``params`` (RunCheck as a dict): planned and checked from
    where the robot is, nothing started; a refusal is ``feasible`` false with its reason."""
    try:
        runs.plan(params)
        detail = None
    except (GoalRejected, MotionRefused) as exc:
        detail = str(exc)
    speed, acceleration, _ = params.peaks()
    stepped = isinstance(params, StepParams)  # sampled, its jump reads as any speed
    return RunCheck(
        feasible=detail is None,
        detail=detail,
        peak_joint_speed_rad_s=None if stepped else peak_joint_speed(controller, params),
        joint_speed_limit_rad_s=controller.settings.limits.joint_speed_rad_s,
        peak_speed_m_s=speed,
        peak_acceleration_m_s2=acceleration,
    ).model_dump()


check_sinusoid = check_run  # the first run type's preview, by its old name


@router.get(
    "/api/tests",
    response_model=list[RunTypeOut],
    response_model_by_alias=True,
    responses=UNAUTHORISED,
    dependencies=[Depends(require_read_token)],  # this router has no reads dependency
)
def list_run_types() -> list[dict[str, Any]]:
    """The run types POST /api/tests/<name> starts, in the registry's order, each with its
    body's JSON schema (fields, bounds, defaults; SI units named by each field's suffix).
    POST /api/tests/hold (hold-in-world) is the drone's: its own body, not listed here."""
    return [
        {
            "name": t.name,
            "doc": t.doc,
            "start": f"/api/tests/{t.name}",
            "check": f"/api/tests/{t.name}/check",
            "schema": t.request.model_json_schema(),
        }
        for t in RUN_TYPES.values()
    ]


def _checker(run_type: RunType) -> Callable[..., Awaitable[dict]]:
    """The route checking a run of ``run_type``: its body is the type's request model."""

    async def check(body: RunRequest, runs: RunsDep, controller: ControllerDep, _: TokenChecked):
        params = body.params()  # GoalRejected (422) for what the schema cannot say
        return await asyncio.to_thread(check_run, runs, controller, params)

    check.__annotations__ = {**check.__annotations__, "body": run_type.request}
    check.__name__ = check.__qualname__ = f"check_{run_type.name}"
    check.__doc__ = (
        f"Plan and check a {run_type.name} run from where the robot is, without moving; "
        "never starts it."
    )
    return check


for _type in RUN_TYPES.values():  # POST /api/tests/sinusoid/check, /chirp/check, ...
    router.add_api_route(
        f"/api/tests/{_type.name}/check",
        _checker(_type),
        methods=["POST"],
        response_model=RunCheck,
        responses={**UNAUTHORISED, **INVALID, **UNAVAILABLE},
    )


@router.get("/vendor/plotly.min.js", include_in_schema=False)
def plotly_js() -> FileResponse:
    """plotly.js from the installed ``plotly`` package (offline, cached by the browser)."""
    if not PLOTLY_JS.exists():
        raise HTTPException(404, "plotly.min.js is missing from the plotly package")
    headers = {"Cache-Control": "public, max-age=86400"}
    return FileResponse(PLOTLY_JS, media_type="text/javascript", headers=headers)

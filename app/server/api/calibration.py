"""Calibration resource (issue 20): start a guided calibration run, read it, apply it."""

from __future__ import annotations

import asyncio
import math
from typing import Annotated, Any, Literal

from fastapi import APIRouter, HTTPException
from fastapi.responses import FileResponse
from pydantic import BaseModel, ConfigDict, Field, model_validator

from app.calibration.fit import CalibrationError
from app.calibration.procedure import CalibrationManager, CalibrationRun
from app.server.api.deps import CalibrationDep, ControlClient, ControllerDep, SettingsDep
from app.server.api.responses import RobotModelOut
from app.server.errors import CONTROL, INVALID, NOT_FOUND

router = APIRouter(tags=["calibration"])
MAX_POSES = 300
FILES = {
    "report.png": "image/png",
    "pairs.csv": "text/csv",
    "touches.csv": "text/csv",
    "result.json": "application/json",
}


class CalibrationRequest(BaseModel):
    """How many poses to visit (a quarter, at least 3, held out) and what to fit."""

    model_config = ConfigDict(extra="forbid", strict=True)
    poses: Annotated[int, Field(ge=12, le=MAX_POSES, description="poses visited")] = 40
    parameters: Literal["offsets", "geometry"] = Field(
        "offsets",
        description="offsets: joint offsets and the measurement frame; geometry: also each "
        "leg's L, l and R",
    )
    source: Literal["motion", "probe"] = Field(
        "motion",
        description="motion: the platform measured from outside (motion capture); probe: "
        "touches of a flat plate at plate_z_m, heights only (what they cannot observe is "
        "reported)",
    )
    measurement: Literal["external", "pose-input"] = Field(
        "external",
        description="motion: what measures the platform. external: the backend's own (the "
        "twin's motion capture; a real bus has none); pose-input: a motion-capture marker on "
        "the platform streamed to the pose input with body 'platform' (POST or WebSocket "
        "/api/mav/pose, or UDP JSON), in the capture system's world frame, the base still",
    )
    plate_z_m: float | None = Field(
        None,
        description="probe: the plate's height in the base frame [m] (z up, below the base)",
    )
    fit_plate_z: bool = Field(
        False, description="probe: also fit an error of the plate's stated height"
    )
    probe: Literal["touch", "model"] | None = Field(
        None,
        description="probe: where the touches come from. touch: the arm touches the plate "
        "with the force-guided touch (straight down from 5 mm above plate_z_m, then back "
        "up; plate_z_m is then the tool tip's height at contact); model: computed from the "
        "twin's true model, the arm not moved (the twin only). Default: touch where the "
        "robot has a contact force estimate and, on the twin, a plate at plate_z_m under "
        "the points; else model",
    )
    touch_speed_m_s: float | None = Field(
        None, gt=0, le=0.1, description="probe by touch: the touch's speed [m/s] ([contact])"
    )
    touch_force_n: float | None = Field(
        None,
        gt=0,
        description="probe by touch: the force each touch stops at [N] (default [contact] "
        "touch_force_n; at most contact.force_limit_n)",
    )

    @model_validator(mode="after")
    def _probe_fields(self) -> CalibrationRequest:
        if self.source == "probe":
            if self.plate_z_m is None:
                raise ValueError("plate_z_m: a probe run needs the plate's height [m]")
            if not math.isfinite(self.plate_z_m) or not -2.0 < self.plate_z_m < 0.0:
                raise ValueError(
                    f"plate_z_m: {self.plate_z_m} m is not below the base (z < 0, in metres)"
                )
            if self.measurement != "external":
                raise ValueError("measurement: a probe run measures by its touches")
            if self.probe == "model" and (
                self.touch_speed_m_s is not None or self.touch_force_n is not None
            ):
                raise ValueError("touch_speed_m_s, touch_force_n: only for probe 'touch'")
        elif self.plate_z_m is not None or self.fit_plate_z:
            raise ValueError("plate_z_m, fit_plate_z: only for source 'probe'")
        elif self.probe is not None or self.touch_speed_m_s or self.touch_force_n:
            raise ValueError("probe, touch_speed_m_s, touch_force_n: only for source 'probe'")
        return self


class CalibrationStarted(BaseModel):
    run_id: str


class CalibrationParameters(BaseModel):
    """The fitted model: joint offsets [rad] and each leg's lengths [m] (nominal where not
    fitted)."""

    joint_offsets_rad: list[float]
    L_m: list[float]
    l_m: list[float]
    R_m: list[float]
    r_m: list[float]


class Progress(BaseModel):
    pose: int = Field(description="poses measured so far")
    poses: int = Field(description="poses to visit (fit and held out)")


class Frame(BaseModel):
    position_m: list[float]
    rpy_rad: list[float]


class CalibrationOut(BaseModel):
    """A calibration run. state: planned, moving, fitting, done, refused (worse than the
    current model on held-out poses: never applied), failed (error says why), aborted
    (POST .../abort), applied.
    RMSE [m] is the root mean square 3D distance between FK and the measurement; *_before
    the current model (its measurement frame fitted), holdout_* on the held-out poses."""

    run_id: str
    state: str
    kind: str
    parameters_fitted: str
    progress: Progress
    error: str | None
    parameters: CalibrationParameters | None
    rmse_before_m: float | None
    rmse_after_m: float | None
    holdout_rmse_before_m: float | None
    holdout_rmse_m: float | None
    condition_number: float | None
    singular_values: list[float]
    unobservable: list[str]
    holdout_poses: int
    measurement_frame: Frame | None
    files: list[str]
    source: str = Field("motion", description="motion or probe")
    measurement: str | None = Field(
        "external", description="motion: external or pose-input (null for a probe run)"
    )
    plate_z_m: float | None = Field(None, description="probe: the plate's stated height [m]")
    probe: str | None = Field(
        None, description="probe: touch (the arm touched the plate) or model (null: motion)"
    )
    plate_error_m: float | None = Field(
        None, description="probe with fit_plate_z: the fitted error of the plate's height [m]"
    )
    unobservable_combinations: list[str] = Field(
        [], description="the directions the data cannot pin, parameter by parameter"
    )


class CalibrationApplied(BaseModel):
    run_id: str
    parameters_applied: str = Field(description="offsets, or geometry (offsets and legs)")
    joint_offsets_rad: list[float] = Field(description="the offsets the controller now uses")
    robot: RobotModelOut = Field(description="the robot model the controller now uses")
    config_written: str | None = Field(description="the config file written, if one is in use")


class CalibrationSummary(BaseModel):
    """A calibration run in the list: its state and RMSEs [m] (None until fitted)."""

    run_id: str
    state: str
    parameters_fitted: str = Field(description="offsets or geometry")
    source: str = Field(description="motion or probe")
    rmse_before_m: float | None
    rmse_after_m: float | None
    holdout_rmse_m: float | None
    error: str | None


def _run(calibration: CalibrationManager, run_id: str) -> CalibrationRun:
    run = calibration.get(run_id)
    if run is None:
        raise HTTPException(404, f"no calibration run {run_id!r}")
    return run


@router.post("/calibration/run", response_model=CalibrationStarted, responses=CONTROL)
async def start_calibration(
    body: CalibrationRequest, calibration: CalibrationDep, _c: ControllerDep, _: ControlClient
) -> dict[str, Any]:
    """Plan the poses (the observability is in GET at once), then move through them,
    measuring at rest, and fit. 409 when the robot may not move (torque off, e-stop, a
    fault, another run); 422 naming the field for bad input."""
    try:
        run = await asyncio.to_thread(
            calibration.start,
            body.poses,
            body.parameters,
            body.source,
            body.plate_z_m,
            body.fit_plate_z,
            body.measurement,
            body.probe,
            body.touch_speed_m_s,
            body.touch_force_n,
        )
    except CalibrationError as exc:
        raise HTTPException(422, str(exc)) from None
    return {"run_id": run.run_id}


@router.get("/calibration", response_model=list[CalibrationSummary])
def list_calibration_runs(calibration: CalibrationDep) -> list[dict[str, Any]]:
    """This server's calibration runs, newest first."""
    return [run.summary() for run in calibration.list()]


@router.post(
    "/calibration/{run_id}/abort", response_model=CalibrationOut, responses={**CONTROL, **NOT_FOUND}
)
async def abort_calibration(
    run_id: str, calibration: CalibrationDep, _c: ControllerDep, _: ControlClient
) -> dict[str, Any]:
    """Stop the run now: the arm holds where it is, the run ends "aborted", and the robot
    takes other commands at once. 404 for an unknown run, 409 for one not running."""
    _run(calibration, run_id)
    return (await asyncio.to_thread(calibration.abort, run_id)).view()


@router.get(
    "/calibration/{run_id}", response_model=CalibrationOut, responses={**NOT_FOUND, **INVALID}
)
def get_calibration_run(run_id: str, calibration: CalibrationDep) -> dict[str, Any]:
    """State, progress, fitted parameters, RMSE before / after / held out [m], the
    identification's condition number, singular values and unobservable parameters."""
    return _run(calibration, run_id).view()


@router.post(
    "/calibration/{run_id}/apply",
    response_model=CalibrationApplied,
    responses={**CONTROL, **NOT_FOUND},
)
async def apply_calibration(
    run_id: str, calibration: CalibrationDep, settings: SettingsDep, _: ControlClient
) -> dict[str, Any]:
    """The controller uses the fitted joint offsets from now on and, for a geometry fit,
    each leg's fitted L, l, R, r as its robot model (IK, FK, the gate's workspace, limits
    and singularity margin, jogs, runs, programs, hold-in-world, the workspace views);
    nothing moves. Written to the config file when the server runs from one (the joints'
    zero offsets, and ``[robot.legs]`` for geometry). 409 for a run not done (refused:
    worse on held-out poses), one fitted against a model no longer in use (a calibration
    applied since), a motion running or another procedure holding the robot."""
    _run(calibration, run_id)
    legs = [joint.calibration() for joint in settings.hardware.joints]  # not the wrist
    return await asyncio.to_thread(calibration.apply, run_id, legs)


@router.get(
    "/calibration/{run_id}/{name}",
    response_class=FileResponse,
    responses={**NOT_FOUND, **INVALID},
)
def get_calibration_file(run_id: str, name: str, calibration: CalibrationDep) -> FileResponse:
    """A run's file: report.png (residuals before and after), pairs.csv (touches.csv for
    a probe run), result.json."""
    run = _run(calibration, run_id)
    path = run.folder / name
    if name not in FILES or not path.is_file():
        raise HTTPException(404, f"run {run_id} has no file {name!r}")
    return FileResponse(path, media_type=FILES[name], filename=name)

"""Tuning resource (issue 21): identify the joints, suggest gains, apply them, revert."""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, HTTPException
from fastapi.responses import FileResponse
from pydantic import BaseModel, ConfigDict, Field

from app.server.api.deps import ControlClient, ControllerDep, TuningDep
from app.server.errors import CONTROL, INVALID, NOT_FOUND
from app.tuning.gains import Target, TuningError
from app.tuning.procedure import TuningManager, TuningRun

router = APIRouter(tags=["tuning"])
FILES = {"bode.png": "image/png", "result.json": "application/json"}


class TargetIn(BaseModel):
    """What the suggested gains aim at (app/tuning/gains.py's rule)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    bandwidth_hz: Annotated[float, Field(ge=0.1, le=100.0, description="closed loop [Hz]")] = (
        Target.bandwidth_hz
    )
    phase_margin_deg: Annotated[float, Field(ge=20.0, le=85.0, description="at least [deg]")] = (
        Target.phase_margin_deg
    )
    overshoot_pct: Annotated[float, Field(gt=0.0, le=50.0, description="step, at most [%]")] = (
        Target.overshoot_pct
    )
    pwm_fraction: Annotated[
        float, Field(ge=0.05, le=1.0, description="peak PWM of the checked step, of the limit")
    ] = Target.pwm_fraction
    feedforward: bool = Field(
        Target.feedforward,
        description="suggest Feedforward 1st / 2nd gains (they act only through the "
        "servo's Profile, which the loop leaves off; the loop's lead time is the default "
        "feed-forward: docs/tuning.md)",
    )


class TuningRequest(BaseModel):
    """The joints (1..3) to identify and tune, and the target."""

    model_config = ConfigDict(extra="forbid", strict=True)
    joints: Annotated[list[int], Field(min_length=1, max_length=3)] = [1, 2, 3]
    target: TargetIn = Field(default_factory=TargetIn)


class TuningApplyRequest(BaseModel):
    """Optional: apply gains that miss the goal on the twin (``checked.met_goal`` false)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    confirm_missed: bool = Field(
        False,
        description="apply even though the twin check found the gains miss the goal (the "
        "409 without it says what they miss)",
    )


class TuningStarted(BaseModel):
    run_id: str


class ServoGains(BaseModel):
    """Position gains in the XM430's register units (0..16383): KpP = p / 128, KiP =
    i / 65536, KdP = d / 16, feed-forward ff1 / 4 (velocity) and ff2 / 4 (acceleration)."""

    p: int
    i: int
    d: int
    ff1: int
    ff2: int


class TrackingOut(BaseModel):
    """The thesis sinusoid on the twin: RMSE per axis (x, y, z) [m] of the FK of the
    encoders against the path, peak PWM and the share of the run with some joint's PWM at
    its limit (fractions)."""

    rmse_m: list[float]
    peak_pwm: float
    at_limit: float


class LongMoveOut(BaseModel):
    """The 70 mm go-tos on the loop's jerk-limited path (along x, down z from (0, 0,
    -0.24) m): per move, overshoot_m [m] past the goal after the path ends and settle_s
    [s] until the tip stays within the limits' settle_band_m of the goal (the watch's
    length, 2 s, when it never does)."""

    overshoot_m: list[float]
    settle_s: list[float]


class CandidateOut(BaseModel):
    """One gain set checked on the twin (app/tuning/twin_check.py): its number (1: the
    first tried), the target variant the rule was given (pwm_fraction: the D cap's
    headroom; overshoot_pct: the model's allowance; integral), the gains per servo id
    (the legs not tuned keep theirs), the sinusoid without (plain) and with (lead) the
    loop's lead, the 20 mm z step's overshoot_pct [%], rest_m [m] at five points, the
    long_move's overshoot and settling, and the limits it misses (failed)."""

    candidate: int
    target: dict[str, Any]
    gains: dict[str, ServoGains]
    plain: TrackingOut
    lead: TrackingOut
    overshoot_pct: float
    rest_m: list[float]
    long_move: LongMoveOut
    failed: list[str]
    passes: bool


class CheckedOut(BaseModel):
    """What the twin check found before the gains were suggested: every candidate, in the
    order tried; chosen: the number of the one suggested; met_goal: whether it passes every
    limit (issue 21's goal: limits); reason: why it was chosen (with none passing, the
    closest, and what it misses); the check's conditions (the loop's lead_s [s], its
    gravity_compensation, seconds [s] of sinusoid measured)."""

    met_goal: bool
    chosen: int
    reason: str
    lead_s: float
    gravity_compensation: bool
    seconds: float
    limits: dict[str, float]
    candidates: list[CandidateOut]


class TuningOut(BaseModel):
    """A tuning run. state: planned, moving, step, chirp, fitting, checking (the candidate
    gains on the twin), done, failed (error says why), aborted (POST .../abort), applied.
    model: per servo id, the fitted K wn^2 / (s^2 + 2 zeta wn s + wn^2) e^{-sT} (gain,
    wn_rad_s, zeta, delay_s, bandwidth_hz, rmse_rad); suggested: per servo id, the gains
    the twin check chose (checked); predicted: per servo id, the model's loop with the
    suggested and the current gains (crossover_hz, phase_margin_deg, bandwidth_hz,
    peak_db, overshoot_pct, settling_s, peak_pwm_fraction, static_error_pct; meets_target
    against the chosen candidate's target); checked: the twin check (null until it is
    done)."""

    run_id: str
    state: str
    joints: list[int]
    target: dict[str, Any]
    error: str | None
    runs: dict[str, str] = Field(description="the step and chirp runs recorded (kind: run id)")
    model: dict[str, dict[str, Any]]
    suggested: dict[str, ServoGains]
    predicted: dict[str, dict[str, Any]]
    checked: CheckedOut | None = None
    files: list[str]


class TuningSummary(BaseModel):
    """A tuning run in the list: its state, joints, and whether the suggested gains met
    the goal on the twin (null until the check is done)."""

    run_id: str
    state: str
    joints: list[int]
    met_goal: bool | None
    error: str | None


class GainsOut(BaseModel):
    gains: dict[str, ServoGains] = Field(description="the gains now in use, per servo id")
    config_written: str | None = Field(description="the config file written, if one is in use")


class TuningApplied(GainsOut):
    run_id: str


def _run(tuning: TuningManager, run_id: str) -> TuningRun:
    run = tuning.get(run_id)
    if run is None:
        raise HTTPException(404, f"no tuning run {run_id!r}")
    return run


@router.post("/tuning/run", response_model=TuningStarted, responses=CONTROL)
async def start_tuning(
    body: TuningRequest, tuning: TuningDep, _c: ControllerDep, _: ControlClient
) -> dict[str, Any]:
    """Move to the start point, record a step and a chirp run, fit each joint's model,
    check the rule's candidate gains on the twin and suggest the one the check chose (GET
    the run for its progress). 409 when the robot may not move (torque
    off, e-stop, a fault, another run, tuned gains in use); 422 naming the field."""
    try:
        target = Target(**body.target.model_dump())
        run = await asyncio.to_thread(tuning.start, tuple(body.joints), target)
    except TuningError as exc:
        raise HTTPException(422, str(exc)) from None
    return {"run_id": run.run_id}


@router.get("/tuning", response_model=list[TuningSummary])
def list_tuning_runs(tuning: TuningDep) -> list[dict[str, Any]]:
    """This server's tuning runs, newest first (a page reloaded finds the one running)."""
    return [tuning.summary(run) for run in tuning.list()]


@router.post("/tuning/revert", response_model=GainsOut, responses=CONTROL)
async def revert_tuning(tuning: TuningDep, _c: ControllerDep, _: ControlClient) -> dict[str, Any]:
    """The gains in use before the last apply, back on the servos. 409 when nothing was
    applied or a motion is running."""
    return await asyncio.to_thread(tuning.revert)


@router.post("/tuning/{run_id}/abort", response_model=TuningOut, responses={**CONTROL, **NOT_FOUND})
async def abort_tuning(
    run_id: str, tuning: TuningDep, _c: ControllerDep, _: ControlClient
) -> dict[str, Any]:
    """Stop the run now: its move, step or chirp run stops (the arm holds where it is),
    the run ends "aborted", and the robot takes other commands at once. 404 for an unknown
    run, 409 for one not running."""
    _run(tuning, run_id)
    return (await asyncio.to_thread(tuning.abort, run_id)).view()


@router.get("/tuning/{run_id}", response_model=TuningOut, responses={**NOT_FOUND, **INVALID})
def get_tuning_run(run_id: str, tuning: TuningDep) -> dict[str, Any]:
    """State, the fitted models, the suggested gains and their predicted effect."""
    return _run(tuning, run_id).view()


@router.post(
    "/tuning/{run_id}/apply", response_model=TuningApplied, responses={**CONTROL, **NOT_FOUND}
)
async def apply_tuning(
    run_id: str,
    tuning: TuningDep,
    _c: ControllerDep,
    _: ControlClient,
    body: TuningApplyRequest | None = None,
) -> dict[str, Any]:
    """The tuned joints' servos use the suggested gains from now on (the previous ones
    kept for POST /api/tuning/revert). 409 for a run not done, a motion running, or gains
    that miss the goal on the twin unless the body says ``{"confirm_missed": true}`` (the
    409 says what they miss)."""
    _run(tuning, run_id)
    confirm = body is not None and body.confirm_missed
    return await asyncio.to_thread(tuning.apply, run_id, confirm)


@router.get(
    "/tuning/{run_id}/{name}", response_class=FileResponse, responses={**NOT_FOUND, **INVALID}
)
def get_tuning_file(run_id: str, name: str, tuning: TuningDep) -> FileResponse:
    """A run's file: bode.png (measured against fitted, per joint), result.json."""
    run = _run(tuning, run_id)
    path = run.folder / name
    if name not in FILES or not path.is_file():
        raise HTTPException(404, f"run {run_id} has no file {name!r}")
    return FileResponse(path, media_type=FILES[name], filename=name)

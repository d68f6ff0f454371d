"""Servos resource (issue 21's servo panel): one servo's gains, read from the servo and
written to it, and a step of its joint with the response it recorded (app/tuning/
servo_panel.py). The servos are the legs' and, with a [wrist], the wrist's (its step a step
of phi, within the wrist's limits). The revert is the tuning's: POST /api/tuning/revert
undoes the last apply or write of the legs' gains."""

from __future__ import annotations

import asyncio
import math
import time
from typing import Annotated, Any, Literal

from fastapi import APIRouter, HTTPException, Request
from pydantic import BaseModel, ConfigDict, Field

from app.config import XM430_CURRENT_LIMIT_A
from app.control.errors import GoalRejected, MotionRefused
from app.runs.logs import read_csv_rows
from app.server.api.deps import (
    CalibrationDep,
    CommandWait,
    ControlClient,
    ControllerDep,
    RunsDep,
    TuningDep,
)
from app.server.api.runs import start_run
from app.server.api.tuning import ServoGains
from app.server.errors import CONTROL, INVALID, UNAVAILABLE, ErrorBody
from app.tuning.servo_panel import (
    GAIN_LIMITS,
    KIND,
    MAX_STEP_RAD,
    MIN_STEP_RAD,
    WRIST,
    panel_joint,
    panel_servo_ids,
    plan_joint_step,
    plan_wrist_step,
    step_record,
    step_response,
    wrist_step_record,
    wrist_step_response,
)
from hardware.bus import PositionGains

router = APIRouter(tags=["servos"])
READ_TIMEOUT_S = 5.0
STEP_WAIT_S = 60.0  # beyond the step's own duration: a starved twin runs slower than the clock
POLL_S = 0.02
NO_SERVO = {
    404: {"model": ErrorBody, "description": "servo_id is not a leg's servo nor the wrist's"}
}
BUSY = {
    409: {
        "model": ErrorBody,
        "description": "a motion is running (gains are read only while the arm rests)",
    }
}


def _gain(name: str, what: str) -> Any:
    low, high = GAIN_LIMITS[name]
    return Annotated[
        int, Field(ge=low, le=high, strict=True, description=f"{what} ({low}..{high})")
    ]


PGain = _gain("p", "Position P Gain, register 84: KpP = p / 128")
IGain = _gain("i", "Position I Gain, register 82: KiP = i / 65536")
DGain = _gain("d", "Position D Gain, register 80: KdP = d / 16")
FF1Gain = _gain("ff1", "Feedforward 1st Gain, register 90 (velocity): ff1 / 4")
FF2Gain = _gain("ff2", "Feedforward 2nd Gain, register 88 (acceleration): ff2 / 4")


class GainsRequest(BaseModel):
    """A servo's five position gains in the XM430's register units, each within its
    register's range (the control table: 0..16383)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    p: PGain
    i: IGain
    d: DGain
    ff1: FF1Gain
    ff2: FF2Gain

    def gains(self) -> PositionGains:
        return PositionGains(self.p, self.i, self.d, self.ff1, self.ff2)


class Range(BaseModel):
    min: float
    max: float


class ServoGainsOut(BaseModel):
    """One servo's gains: ``servo`` as the servo's own registers hold them (read now),
    ``in_use`` as the loop set them (they differ only if something else wrote the servo;
    the wrist's: as read), the registers' ``limits``, the step sizes a step accepts
    (``step_rad``: its magnitude, either sign [rad]) and whether POST /api/tuning/revert
    has something to undo (``revertable``: the legs' gains only). ``joint`` is 1..3 for a
    leg, 4 for the wrist (``role``); ``limits_rad`` the joint's range a step must stay in
    (the wrist's limits; null for a leg: its limits are the gate's, checked per step)."""

    servo_id: int
    joint: int
    role: Literal["leg", "wrist"]
    limits_rad: Range | None
    servo: ServoGains
    in_use: ServoGains
    limits: dict[str, Range]
    step_rad: Range
    revertable: bool


class GainsWritten(BaseModel):
    """The write: ``servo`` read back from the servo's registers after it, the gains now in
    use per leg servo id, and the config file written (null without one)."""

    servo_id: int
    servo: ServoGains
    gains: dict[str, ServoGains]
    config_written: str | None


class JointStepRequest(BaseModel):
    """A step of the servo's joint from where the arm rests."""

    model_config = ConfigDict(extra="forbid", strict=True)
    step_rad: Annotated[
        float,
        Field(
            ge=-MAX_STEP_RAD,
            le=MAX_STEP_RAD,
            allow_inf_nan=False,
            description=f"the step [rad], {math.degrees(MIN_STEP_RAD):g} to "
            f"{math.degrees(MAX_STEP_RAD):g} deg either way",
        ),
    ]
    duration_s: Annotated[
        float, Field(ge=0.5, le=5.0, allow_inf_nan=False, description="the record [s]")
    ] = 1.0


class StepFigures(BaseModel):
    """The measured response against its own start and end (docs/tuning.md): rise_time_s
    (10 to 90 % of the change), delay_s (to 10 %), overshoot_pct (beyond the end value, % of
    the change), settling_s (within settle_band_rad of the end value from then on; null:
    not settled within the record), steady_error_rad (the final goal minus the end value),
    moved_rad and moved_fraction (the measured change, and over the goal's); null where
    the record cannot say (no motion, a stopped run)."""

    rise_time_s: float | None
    delay_s: float | None
    overshoot_pct: float | None
    settling_s: float | None
    settle_band_rad: float | None
    steady_error_rad: float | None
    moved_rad: float | None
    moved_fraction: float | None


class JointStepOut(BaseModel):
    """The step's run (kind joint-step: its logs and report as any run's), how it ended
    (state done, or aborted with the reason: an e-stop, a fault) and its record, one
    sample per loop tick: t_s [s] from the step (the clock: the twin's simulated time, or
    the loop's), the joint's goal_rad and measured_rad [rad]; and its figures."""

    run_id: str
    servo_id: int
    joint: int
    state: str
    reason: str | None
    step_rad: float
    start_rad: list[float]
    clock: Literal["sim_time_s", "t_s"]
    t_s: list[float]
    goal_rad: list[float]
    measured_rad: list[float]
    figures: StepFigures


def _joint(controller: Any, servo_id: int) -> int:
    """The panel's joint of ``servo_id``: 1..3 a leg's, 4 the wrist's; 404 otherwise."""
    try:
        return panel_joint(controller, servo_id)
    except KeyError:
        ids = panel_servo_ids(controller)
        raise HTTPException(
            404, f"servo_id: {servo_id} is not a servo of this robot ({ids})"
        ) from None


async def _read(controller: Any, servo_id: int) -> PositionGains:
    read = await asyncio.to_thread(lambda: controller.read_gains().result(READ_TIMEOUT_S))
    return read[servo_id]


class ServoCurrentRequest(BaseModel):
    """The legs' servos' operating mode and Goal Current (Dynamixel Goal Current, 102)."""

    model_config = ConfigDict(extra="forbid", strict=True)  # "1" and true are no currents
    operating_mode: Literal["position", "current_based_position"] = Field(
        description="position (Dynamixel mode 3), or current_based_position (mode 5: each "
        "joint's motor current, and so its torque, bounded by goal_current_a)"
    )
    goal_current_a: list[Annotated[float, Field(gt=0, le=XM430_CURRENT_LIMIT_A)]] = Field(
        min_length=3,
        max_length=3,
        description="Goal Current per leg in joint order [A], each > 0 and <= 3.209 (the "
        "XM430-W210's Current Limit)",
    )


class ServoCurrentOut(BaseModel):
    operating_mode: Literal["position", "current_based_position"]
    goal_current_a: list[float] = Field(description="per leg in joint order [A], as written")


@router.put(
    "/servos/current",
    response_model=ServoCurrentOut,
    responses={
        **CONTROL,
        409: {
            "model": ErrorBody,
            "description": "torque is on (the mode is an EEPROM item: turn torque off "
            "first), a motion, a calibration or a tuning runs, or another client holds "
            "control",
        },
    },
)
async def put_servo_current(
    body: ServoCurrentRequest,
    controller: ControllerDep,
    tuning: TuningDep,
    calibration: CalibrationDep,
    wait_s: CommandWait,
    _: ControlClient,
) -> dict[str, Any]:
    """Write the legs' operating mode (with torque off) and then their Goal Current, and
    answer what is in use (GET /api/status shows it as servo_mode and goal_current_a).
    422 naming the field for a bad value (nothing is written); 409 while torque is on or
    while a motion, a run, a calibration or a tuning runs. Not written to the config file:
    [hardware] operating_mode and goal_current_a set it at start."""
    if calibration.running():
        raise MotionRefused("a calibration run is in progress: the servo mode changes once it ends")
    if tuning.running():
        raise MotionRefused("a tuning run is in progress: the servo mode changes once it ends")
    future = controller.set_servo_current(body.operating_mode, body.goal_current_a)
    return await asyncio.wait_for(asyncio.wrap_future(future), wait_s)


@router.get(
    "/servos/{servo_id}/gains",
    response_model=ServoGainsOut,
    responses={**NO_SERVO, **BUSY, **UNAVAILABLE, **INVALID},
)
async def read_servo_gains(servo_id: int, controller: ControllerDep, tuning: TuningDep):
    """The servo's position gains read from its registers (80..91) now, beside the ones
    the loop set; 409 while a motion runs (the read holds the loop's tick), 503 when the
    servo does not answer."""
    joint = _joint(controller, servo_id)
    servo = await _read(controller, servo_id)
    wrist = controller.settings.wrist
    return {
        "servo_id": servo_id,
        "joint": joint,
        "role": "wrist" if joint == WRIST else "leg",
        "limits_rad": (
            {"min": wrist.min_angle_rad, "max": wrist.max_angle_rad} if joint == WRIST else None
        ),
        "servo": servo.as_dict(),
        "in_use": (servo if joint == WRIST else controller.gains[servo_id]).as_dict(),
        "limits": {k: {"min": lo, "max": hi} for k, (lo, hi) in GAIN_LIMITS.items()},
        "step_rad": {"min": MIN_STEP_RAD, "max": MAX_STEP_RAD},
        "revertable": tuning.revertable,
    }


@router.post(
    "/servos/{servo_id}/gains",
    response_model=GainsWritten,
    responses={**CONTROL, **NO_SERVO},
)
async def write_servo_gains(
    servo_id: int,
    body: GainsRequest,
    controller: ControllerDep,
    tuning: TuningDep,
    calibration: CalibrationDep,
    _: ControlClient,
):
    """Write the servo's five gains (the other legs keep theirs), read them back from it,
    and write them to the config file when the server runs from one; POST
    /api/tuning/revert restores the set they replaced. 422 naming the field outside its
    register's range (nothing is written); 409 while a motion, a run, a calibration or a
    tuning runs."""
    joint = _joint(controller, servo_id)
    if calibration.running():
        raise MotionRefused("a calibration run is in progress: gains change once it ends")
    if joint == WRIST:
        written = await asyncio.to_thread(_write_wrist, controller, tuning, servo_id, body.gains())
    else:
        written = await asyncio.to_thread(tuning.write, servo_id, body.gains())
    servo = await _read(controller, servo_id)
    return {"servo_id": servo_id, "servo": servo.as_dict(), **written}


def _write_wrist(
    controller: Any, tuning: Any, servo_id: int, gains: PositionGains
) -> dict[str, Any]:
    """The wrist's gains written (the legs keep theirs), refused as a leg's write is while
    a tuning, a run or a procedure runs; not kept for revert nor written to the config file
    (the config holds the legs' gains)."""
    if tuning.running():
        raise MotionRefused("a tuning run is in progress: gains change once it ends")
    if (other := controller.owner.busy()) is not None:
        raise MotionRefused(other)
    in_use = controller.set_gains({**controller.gains, servo_id: gains}).result(timeout=5.0)
    return {"gains": {str(k): g.as_dict() for k, g in in_use.items()}, "config_written": None}


@router.post(
    "/servos/{servo_id}/step",
    response_model=JointStepOut,
    responses={**CONTROL, **NO_SERVO},
)
async def step_servo(
    request: Request,
    servo_id: int,
    body: JointStepRequest,
    controller: ControllerDep,
    runs: RunsDep,
    _: ControlClient,
) -> dict[str, Any]:
    """Step the servo's joint by step_rad from where the arm rests (the others held),
    record it at the loop rate as a run (kind joint-step) and answer when it has ended,
    with its record and figures. Checked like every run before anything moves: 422 naming
    step_rad (too small or large, its end outside the joint limits or the workspace);
    409 when the arm does not rest, its state is stale, or it may not move."""
    joint = _joint(controller, servo_id)
    if joint == WRIST:  # a step of phi, the legs held
        params: Any = plan_wrist_step(controller, body.step_rad, body.duration_s)
        record, respond = wrist_step_record(params, servo_id), wrist_step_response
        start = [float(params.start_phi_rad)]
    else:
        params = plan_joint_step(controller, servo_id, body.step_rad, body.duration_s)
        record, respond = step_record(params, servo_id), step_response
        start = list(params.start_rad)
    try:
        started = await start_run(request, runs, params, KIND, record)
    except GoalRejected as exc:  # the batch check: name the field it came from
        raise GoalRejected(f"step_rad: the step is {exc.reason}") from None
    run = runs.get(started["run_id"])
    assert run is not None  # launched: the manager keeps it
    deadline = time.monotonic() + body.duration_s + STEP_WAIT_S
    while run.state == "running":
        if time.monotonic() > deadline:
            await asyncio.to_thread(runs.abort, run.run_id, "the step did not end in time")
            raise HTTPException(
                503, f"the step run {run.run_id} did not end within {STEP_WAIT_S:g} s: aborted"
            )
        await asyncio.sleep(POLL_S)
    rows = await asyncio.to_thread(read_csv_rows, run.folder / "log.csv")
    return {
        "run_id": run.run_id,
        "servo_id": servo_id,
        "joint": joint,
        "state": run.state,
        "reason": run.reason,
        "step_rad": params.step_rad,
        "start_rad": start,
        **respond(rows, params),
    }

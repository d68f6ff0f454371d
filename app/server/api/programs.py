"""Programs resource: check a G-code program on the virtual robot before anything moves.

``POST /api/programs/check`` plans the program from where the robot is (or ``start_m``)
and runs every loop sample through the gate's checks, the joint acceleration and the
servo torque (app/programs/). Nothing moves: the answer is the report. A program that
cannot be read is a 422 naming its line and word; one that reads but fails a check is a
200 with ``ok: false`` and its violations.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from fastapi import APIRouter
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field

from app.programs.check import check_program
from app.programs.errors import ProgramError
from app.server.api.deps import ControllerDep, SceneDep, SettingsDep, TokenChecked
from app.server.api.models import ReachVector3
from app.server.errors import UNAUTHORISED, UNAVAILABLE

router = APIRouter(prefix="/programs", tags=["programs"])


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


class ViolationOut(BaseModel):
    line: int = Field(description="program line (1-based)")
    kind: str = Field(description="workspace, ceiling, ik, joint_limit, joint_speed, ...")
    message: str
    t_s: float = Field(description="first offending sample, from the program's start [s]")
    point_m: list[float] = Field(description="its point in the base frame [m]")


class ProgramReportOut(BaseModel):
    """The check's report (app/programs/check.py ProgramReport)."""

    ok: bool
    duration_s: float
    length_m: float
    violations: list[ViolationOut]
    path_m: list[list[float]] = Field(description="the path decimated for drawing [m]")
    peak_joint_speed_rad_s: float | None
    peak_joint_acceleration_rad_s2: float | None
    worst_dexterity: float | None
    worst_torque_ratio: float | None
    lines: int
    segments: int
    samples: int
    period_s: float
    chord_tolerance_m: float
    start_m: list[float]
    work_offset_m: list[float]
    notes: list[str]


class ProgramErrorOut(BaseModel):
    detail: str = Field(description="line N: WORD: reason")
    line: int | None = Field(description="program line (1-based)")
    word: str = Field(description="the word at fault ('' when none is)")


NOT_READABLE: dict[int, dict[str, Any]] = {
    422: {"model": ProgramErrorOut, "description": "the program cannot be read or planned"}
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


@router.post(
    "/check",
    response_model=ProgramReportOut,
    responses={**NOT_READABLE, **UNAUTHORISED, **UNAVAILABLE},
)
def check(
    body: ProgramRequest,
    controller: ControllerDep,
    settings: SettingsDep,
    _: TokenChecked,
    scene: SceneDep,
) -> Any:
    """Plan the program and check every loop sample (workspace with margin and ceiling,
    IK on the followed branch, joint limits, speed and acceleration, singularity margin,
    servo torque); all violations by line. Moves nothing."""
    start, near = (
        (np.asarray(body.start_m), None) if body.start_m is not None else _start(controller)
    )
    notes = []
    if start is None:
        notes.append("the robot's position is unknown: checked from programs.start_m")
    try:
        checked = check_program(
            body.gcode,
            settings,
            gate=controller.gate,
            start_m=start,
            work_offset_m=body.work_offset_m,
            near=near,
        )
    except ProgramError as exc:
        return JSONResponse(
            {"detail": str(exc), "line": exc.line or None, "word": exc.word}, status_code=422
        )
    report = checked.report.to_dict()
    report["notes"] = notes + report["notes"]
    if scene is not None:  # the checked path in the 3D scene, violations in red
        scene.show_program(report)
    return report

"""Robot resource: status, goals, jogging, moves, torque, e-stop, reset and the lease."""

from __future__ import annotations

import asyncio
from concurrent.futures import Future
from typing import Any

from fastapi import APIRouter, HTTPException

from app.server.api import serialize
from app.server.api.deps import ControlClient, ControllerDep, LeaseDep, SettingsDep, TokenChecked
from app.server.api.models import (
    Accepted,
    GoalRequest,
    JogRequest,
    LeaseRequest,
    MoveRequest,
    TorqueRequest,
)
from app.server.api.responses import LeaseOut, StatusOut
from app.server.errors import CONFLICT, CONTROL, INVALID, UNAUTHORISED, UNAVAILABLE

router = APIRouter(tags=["robot"])
COMMAND_TIMEOUT_S = 2.0


async def _outcome(future: Future) -> Accepted:
    """Wait for the control thread to run a command; its exceptions map to HTTP errors."""
    result = await asyncio.wait_for(asyncio.wrap_future(future), COMMAND_TIMEOUT_S)
    return Accepted(result=result)


@router.get("/status", response_model=StatusOut, responses=UNAVAILABLE)
def get_status(controller: ControllerDep) -> dict[str, Any]:
    """Mode, backend, faults, joints, measured and commanded platform, goal and loop timing."""
    return serialize.status(controller)


@router.post("/goal", response_model=Accepted, responses=CONTROL)
async def post_goal(body: GoalRequest, controller: ControllerDep, _: ControlClient):
    """Move the platform to a goal (base frame); refused with the nearest point if outside."""
    return await _outcome(controller.set_goal(body.position_m))


@router.post("/jog", response_model=Accepted, responses=CONTROL)
async def post_jog(body: JogRequest, controller: ControllerDep, _: ControlClient):
    """A relative step [m] (``delta_m``), clamped onto the workspace; or hold-to-move
    (``velocity_m_s``): the jog moves only while this is repeated, stopping 0.2 s after the
    last one (a dead man's switch for browsers), and a zero velocity stops it."""
    if body.velocity_m_s is not None:
        return await _outcome(controller.hold_jog(body.velocity_m_s))
    return await _outcome(controller.jog(body.delta_m))


@router.post("/move", response_model=Accepted, responses=CONTROL)
async def post_move(body: MoveRequest, controller: ControllerDep, _: ControlClient):
    """Smooth move-to a point or joint angles, along a Cartesian or joint-space path."""
    future = controller.move(
        point=body.position_m,
        joints=body.joints_rad,
        duration_s=body.duration_s,
        joint_space=body.space == "joint",
    )
    return await _outcome(future)


@router.post("/torque", response_model=Accepted, responses=CONTROL)
async def post_torque(body: TorqueRequest, controller: ControllerDep, _: ControlClient):
    """Enable torque (holding where the robot is) or relax the servos."""
    return await _outcome(controller.set_torque(body.enabled))


@router.post(
    "/estop", response_model=Accepted, responses={**UNAUTHORISED, **INVALID, **UNAVAILABLE}
)
async def post_estop(controller: ControllerDep, _: TokenChecked):
    """Stop at once; holds or releases torque per config. Needs no lease: anyone may stop."""
    return await _outcome(controller.estop())


@router.post("/reset", response_model=Accepted, responses=CONTROL)
async def post_reset(controller: ControllerDep, _: ControlClient):
    """Clear e-stop and faults; reboots servos that report hardware errors."""
    return await _outcome(controller.reset())


@router.get("/lease", response_model=LeaseOut)
def get_lease(lease: LeaseDep) -> dict[str, Any]:
    """Who holds control now (null when nobody does)."""
    return {"holder": lease.holder if lease.active() else None}


@router.post("/lease", response_model=LeaseOut, responses={**UNAUTHORISED, **CONFLICT, **INVALID})
def post_lease(
    body: LeaseRequest, lease: LeaseDep, settings: SettingsDep, _: TokenChecked
) -> dict[str, Any]:
    """Take the control lease; taking it from another client needs take_over=true."""
    if lease.active() and lease.holder != body.client and not body.take_over:
        raise HTTPException(409, f"control is held by {lease.holder!r}; set take_over=true")
    lease.renew(body.client, settings.server.lease_timeout_s)
    return {"holder": body.client}

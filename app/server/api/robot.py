"""Robot resource: status, goals, jogging, moves, torque, e-stop, reset and the lease."""

from __future__ import annotations

import asyncio
from concurrent.futures import Future
from dataclasses import asdict
from typing import Annotated, Any

from fastapi import APIRouter, Header, HTTPException, Request

from app.control.authority import LeaseHeld
from app.link.codec import decode
from app.server import estop
from app.server.api import serialize
from app.server.api.deps import (
    AuthorityDep,
    CommandWait,
    ControlClient,
    ControllerDep,
    EstopReceiptsDep,
    TokenChecked,
    WorldDep,
)
from app.server.api.models import (
    Accepted,
    GoalRequest,
    JogRequest,
    LeaseRequest,
    MoveRequest,
    TorqueRequest,
)
from app.server.api.responses import LeaseOut, LeaseTaken, StatusOut
from app.server.errors import CONFLICT, CONTROL, INVALID, UNAUTHORISED, UNAVAILABLE
from app.server.estop import EstopReceipt, merged

router = APIRouter(tags=["robot"])


async def _outcome(future: Future, timeout_s: float) -> Accepted:
    """Wait up to ``timeout_s`` [s] for the control thread to run a command (a 503 past it:
    ``server.command_timeout_s``); its exceptions map to HTTP errors."""
    result = await asyncio.wait_for(asyncio.wrap_future(future), timeout_s)
    return Accepted(result=result)


@router.get("/status", response_model=StatusOut, responses=UNAVAILABLE)
def get_status(controller: ControllerDep, receipts: EstopReceiptsDep) -> dict[str, Any]:
    """Mode, backend, faults, joints, the measured and commanded tool tip, the platform
    centre, the wrist angle, the goal and loop timing."""
    node = controller.node_status()  # as the node last said: no request waits on it
    node_receipt = decode(EstopReceipt, node.get("estop") or {})
    receipt = merged(receipts.latest(), node_receipt)  # the node's listener and /api/estop
    return serialize.status(controller.snapshot(), receipt, node.get("pose"))


@router.post("/goal", response_model=Accepted, responses=CONTROL)
async def post_goal(
    body: GoalRequest, controller: ControllerDep, wait_s: CommandWait, _: ControlClient
):
    """Move the tool tip to a goal (base frame) at wrist angle ``phi_rad``; refused with the
    nearest tip if the platform point it implies is outside the workspace."""
    return await _outcome(controller.set_goal(body.position_m, body.phi_rad), wait_s)


@router.post("/jog", response_model=Accepted, responses=CONTROL)
async def post_jog(
    body: JogRequest, controller: ControllerDep, wait_s: CommandWait, _: ControlClient
):
    """A relative step [m] (``delta_m``), clamped onto the workspace; or hold-to-move
    (``velocity_m_s``): the jog moves only while this is repeated, braking 0.15 s after the
    last one (a dead man's switch for browsers), and a zero velocity stops it."""
    if body.velocity_m_s is not None:
        return await _outcome(controller.hold_jog(body.velocity_m_s), wait_s)
    return await _outcome(controller.jog(body.delta_m), wait_s)


@router.post("/move", response_model=Accepted, responses=CONTROL)
async def post_move(
    body: MoveRequest, controller: ControllerDep, wait_s: CommandWait, _: ControlClient
):
    """Smooth move-to a point or joint angles, along a Cartesian or joint-space path."""
    future = controller.move(
        point=body.position_m,
        joints=body.joints_rad,
        duration_s=body.duration_s,
        joint_space=body.space == "joint",
        phi_rad=body.phi_rad,
    )
    return await _outcome(future, wait_s)


@router.post("/stop", response_model=Accepted, responses=CONTROL)
async def post_stop(controller: ControllerDep, wait_s: CommandWait, _: ControlClient):
    """Stop the active motion (a move, a run, a touch, a press): the arm holds where it is
    commanded, torque stays on, nothing to reset (not an e-stop). ``result``: whether a
    motion was running."""
    return await _outcome(controller.stop_any(), wait_s)


@router.post("/torque", response_model=Accepted, responses=CONTROL)
async def post_torque(
    body: TorqueRequest, controller: ControllerDep, wait_s: CommandWait, _: ControlClient
):
    """Enable torque (holding where the robot is) or relax the servos."""
    return await _outcome(controller.set_torque(body.enabled), wait_s)


@router.post("/estop", response_model=Accepted, responses=UNAVAILABLE)
async def post_estop(
    request: Request, _: ControllerDep, receipts: EstopReceiptsDep, wait_s: CommandWait
):
    """Stop at once; holds or releases torque per config. Open to anyone (no token, no
    lease): whoever sees the robot about to hurt someone may stop it. Latched before
    routing by the outermost middleware (app/server/estop.py); also served by the e-stop
    listener on its own port (``/api/info``'s ``estop_port``). An optional ``?press=`` id
    (1-64 of A-Z a-z 0-9 _ -; anything else is ignored, never refused) makes the requests of
    one press by several paths count once. Its wall-clock time of arrival (the first of
    the press) is in GET /api/status (``estop_received_unix_s``): the page's latency is
    measured from it."""
    latched = request.scope.get(estop.SCOPE_KEY)
    route = receipts.press("route", estop.valid_press(request.query_params.get("press")))
    return await _outcome(latched if latched is not None else route, wait_s)


@router.post("/reset", response_model=Accepted, responses=CONTROL)
async def post_reset(
    controller: ControllerDep, world: WorldDep, wait_s: CommandWait, _: ControlClient
):
    """Clear e-stop and faults; reboots servos that report hardware errors; restarts a pose
    input (UDP, MAVLink) whose listener died (GET /api/mav/pose ``sources``)."""
    await asyncio.to_thread(world.restart_inputs)
    return await _outcome(controller.reset(), wait_s)


@router.get("/lease", response_model=LeaseOut)
def get_lease(authority: AuthorityDep) -> dict[str, Any]:
    """Whether control is held, by which display name, since when; never the lease id."""
    return asdict(authority.view())


@router.post("/lease", response_model=LeaseTaken, responses={**UNAUTHORISED, **CONFLICT, **INVALID})
def post_lease(body: LeaseRequest, authority: AuthorityDep, _: TokenChecked) -> dict[str, Any]:
    """Take control: a new secret lease id to send as ``X-Lease`` with each command.
    Taking it from another client (one whose lease has not lapsed) needs take_over=true
    (and the token, where one is set); ``took_over_from`` then says whose it was."""
    try:
        lease_id, previous = authority.take_from(body.client, body.take_over)
    except LeaseHeld as exc:
        raise HTTPException(409, str(exc)) from None
    return {
        "lease_id": lease_id,
        "holder": body.client,
        "timeout_s": authority.timeout_s,
        "took_over_from": asdict(previous) if previous.held else None,
    }


@router.delete("/lease", response_model=LeaseOut, responses={**UNAUTHORISED, **CONFLICT, **INVALID})
def delete_lease(
    authority: AuthorityDep,
    _: TokenChecked,
    x_lease: Annotated[str | None, Header(description="the lease id to give back")] = None,
) -> dict[str, Any]:
    """Give control back (the holder's lease id in ``X-Lease``); 409 for any other id (the
    lease stays with its holder)."""
    if not authority.release(x_lease):
        raise HTTPException(409, "X-Lease is not the current lease: control did not change")
    return asdict(authority.view())

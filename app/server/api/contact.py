"""Contact: the tip's force estimate, touch and the compliant press (docs/contact.md)."""

from __future__ import annotations

import asyncio
from concurrent.futures import Future
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field

from app.control.errors import GoalRejected
from app.fields import Vector3
from app.server.api import serialize
from app.server.api.deps import CommandWait, ControlClient, ControllerDep, SettingsDep, WorldDep
from app.server.api.mav import check_external, check_goal
from app.server.api.models import Accepted
from app.server.errors import CONTROL, UNAVAILABLE
from app.world.drone_sim import DroneSimParams, SimulatedDrone

router = APIRouter(tags=["contact"])

Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class TouchRequest(_Body):
    """A guarded move along ``direction`` (base frame) that stops at ``force_n``."""

    direction: Vector3 = Field(description="the direction to move in, base frame (normalised)")
    speed_m_s: Positive | None = Field(None, description="approach speed [m/s] (<= 0.1)")
    force_n: Positive | None = Field(None, description="the set force to stop at [N]")
    max_travel_m: Positive | None = Field(None, description="travel before 'no contact' [m]")
    retract_m: Annotated[float, Field(ge=0, allow_inf_nan=False)] = Field(
        0.0, description="move back this far after the touch [m] (0: stay pressed)"
    )


class PressHold(_Body):
    """The hold in the world a press rides on (as POST /api/hold)."""

    position_m: Vector3 | None = Field(None, description="world goal [m] (null: where it is)")
    source: Literal["external", "simulated"] = "external"
    latency_compensation: bool = True


class PressRequest(_Body):
    """Press ``force_n`` along ``direction`` and hold position across it."""

    direction: Vector3 = Field(description="the pressed direction, in ``frame``")
    force_n: Positive = Field(description="the set contact force [N]")
    frame: Literal["base", "world"] = Field(
        "base", description="base: from where the tip is; world: on a hold in the world"
    )
    duration_s: Positive | None = Field(None, description="end after this long [s]")
    hold: PressHold | None = Field(None, description="with frame 'world': the hold")


async def _outcome(future: Future, timeout_s: float) -> Accepted:
    """The loop's answer; a value it refused (ValueError naming the field) is a 422."""
    try:
        result = await asyncio.wait_for(asyncio.wrap_future(future), timeout_s)
    except ValueError as exc:
        raise GoalRejected(str(exc)) from None
    return Accepted(result=result)


@router.get("/contact", responses=UNAVAILABLE)
def get_contact(controller: ControllerDep, settings: SettingsDep) -> dict[str, Any]:
    """The tip's contact force now (force_n, std_n [N], base frame, the force the tip
    applies), the last touch's result and the limits in force."""
    snap = controller.snapshot()
    contact = settings.contact
    return {
        "estimate": serialize.contact(snap),
        "touch": serialize.touch(snap),
        "limits": {
            "force_limit_n": contact.force_limit_n,
            "collision_stop": contact.collision_stop,
            "collision_force_n": contact.collision_force_n,
            "detect_force_n": contact.detect_force_n,
            "press_travel_m": contact.press_travel_m,
        },
        "defaults": {
            "speed_m_s": contact.touch_speed_m_s,
            "force_n": contact.touch_force_n,
            "max_travel_m": contact.touch_max_travel_m,
        },
    }


@router.post("/contact/touch", response_model=Accepted, responses=CONTROL)
async def post_touch(
    body: TouchRequest, controller: ControllerDep, wait_s: CommandWait, _: ControlClient
) -> Accepted:
    """Touch: move along ``direction`` until the contact force reaches ``force_n``; the
    result (contact point, force, peak) in GET /api/contact and /api/status."""
    values = {
        k: v
        for k, v in body.model_dump().items()
        if k in ("speed_m_s", "force_n", "max_travel_m", "retract_m") and v is not None
    }
    return await _outcome(controller.touch(body.direction, **values), wait_s)


@router.post("/contact/press", response_model=Accepted, responses=CONTROL)
async def post_press(
    body: PressRequest,
    controller: ControllerDep,
    world: WorldDep,
    wait_s: CommandWait,
    _: ControlClient,
) -> Accepted:
    """Compliant press: ``force_n`` along ``direction``, position held across it; with
    frame "world" on a hold in the world while the drone drifts."""
    hold_args = None
    if body.frame == "world":
        hold = body.hold or PressHold()
        goal = None if hold.position_m is None else np.asarray(hold.position_m, dtype=float)
        simulated = DroneSimParams() if hold.source == "simulated" else None
        if simulated is None:  # as POST /api/tests/hold: a fresh pose, the goal inside
            check_external(await asyncio.to_thread(world.pose_status, "drone"), goal, controller)
        elif goal is not None:  # the simulated drone starts at its pose at t = 0
            start = SimulatedDrone(simulated).true_state(0.0)[0]
            check_goal(start, goal, controller, "at the simulated drone's start")
        hold_args = world.hold(goal, simulated, hold.latency_compensation).remote_args()
    elif body.hold is not None:
        raise GoalRejected("hold: only with frame 'world'")
    future = controller.press(body.direction, body.force_n, body.frame, body.duration_s, hold_args)
    return await _outcome(future, wait_s)

"""The robot node's ROS 2 side: its topics and inputs, and arming the ROS goal input."""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, Header, HTTPException
from pydantic import Field

from app.server.api.deps import CommandWait, ControlClient, ControllerDep, Ros2ArmingDep
from app.server.api.models import _Body
from app.server.errors import CONTROL, UNAVAILABLE

router = APIRouter(tags=["ros2"])


class GoalInputRequest(_Body):
    enabled: bool = Field(
        description="true: goals from the ROS goal topic move the robot while you hold "
        "control (and this station the link); false: they are refused and counted"
    )


@router.get("/ros2", responses=UNAVAILABLE)
def get_ros2(controller: ControllerDep, arming: Ros2ArmingDep) -> dict[str, Any]:
    """The robot node's ROS 2 side as it last said: ``publisher`` (node, form, distro,
    each topic's name, type, key and samples sent), ``pose_input`` and ``goal_input``
    (topic, type, state none / ok / silent, age [s], received, accepted, refused by
    reason, dropped as too fast, the last refusal; the goal input's ``armed``); null where
    the node has no ROS side (no Zenoh session) or the config turns a part off; and
    ``disarmed_because``: why the station last disarmed the goal input (null: it did not)."""
    ros = controller.node_status().get("ros2")
    view = (
        ros if isinstance(ros, dict) else dict.fromkeys(("publisher", "pose_input", "goal_input"))
    )
    return view | {"disarmed_because": arming.disarmed_because}


@router.put(
    "/ros2/goals",
    responses={**CONTROL, 409: {"description": "no ROS goal input, or the robot is busy"}},
)
async def put_ros2_goals(
    body: GoalInputRequest,
    arming: Ros2ArmingDep,
    wait_s: CommandWait,
    _: ControlClient,
    x_lease: Annotated[str | None, Header(description="lease_id from POST /api/lease")] = None,
) -> dict[str, Any]:
    """Arm or disarm the ROS goal input (``[ros2] goal_input`` in the robot node's config)
    for the holder of the control lease. It is disarmed again as soon as that lease is
    given back, lapses or changes hands, a procedure or a run holds the robot (409 while
    one does), or this station loses or takes the robot node's link again. Answers the
    ROS side's status as the node gives it (GET /api/ros2)."""
    try:
        if body.enabled:
            future = arming.arm(x_lease)
        else:
            future = arming.disarm("the operator disarmed them")
        return await asyncio.wait_for(asyncio.wrap_future(future), wait_s)
    except ValueError as exc:
        raise HTTPException(409, str(exc)) from None

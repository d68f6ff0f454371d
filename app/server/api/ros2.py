"""The robot node's ROS 2 side: its topics and inputs, and arming the ROS goal input."""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import APIRouter, HTTPException
from pydantic import Field

from app.server.api.deps import CommandWait, ControlClient, ControllerDep
from app.server.api.models import _Body
from app.server.errors import CONTROL, UNAVAILABLE

router = APIRouter(tags=["ros2"])


class GoalInputRequest(_Body):
    enabled: bool = Field(
        description="true: goals from the ROS goal topic move the robot while you hold "
        "control (and this station the link); false: they are refused and counted"
    )


@router.get("/ros2", responses=UNAVAILABLE)
def get_ros2(controller: ControllerDep) -> dict[str, Any]:
    """The robot node's ROS 2 side as it last said: ``publisher`` (node, form, distro,
    each topic's name, type, key and samples sent), ``pose_input`` and ``goal_input``
    (topic, type, state none / ok / silent, age [s], received, accepted, refused by
    reason, dropped as too fast, the last refusal; the goal input's ``armed``); null where
    the node has no ROS side (no Zenoh session) or the config turns a part off."""
    ros = controller.node_status().get("ros2")
    return (
        ros
        if isinstance(ros, dict)
        else {
            "publisher": None,
            "pose_input": None,
            "goal_input": None,
        }
    )


@router.put("/ros2/goals", responses={**CONTROL, 409: {"description": "no ROS goal input"}})
async def put_ros2_goals(
    body: GoalInputRequest, controller: ControllerDep, wait_s: CommandWait, _: ControlClient
) -> dict[str, Any]:
    """Arm or disarm the ROS goal input (``[ros2] goal_input`` in the robot node's config)
    for the holder of the control lease. It is disarmed again when this station loses or
    hands over the robot node's link. Answers the ROS side's status (GET /api/ros2)."""
    try:
        future = controller.request("ros_goals", {"enabled": body.enabled})
        return await asyncio.wait_for(asyncio.wrap_future(future), wait_s)
    except ValueError as exc:
        raise HTTPException(409, str(exc)) from None

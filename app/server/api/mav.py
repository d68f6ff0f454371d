"""Drone side of the API: pose input (HTTP, WebSocket), hold-in-world, the hold test."""

from __future__ import annotations

import asyncio
import math
from dataclasses import asdict
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, WebSocket
from pydantic import BaseModel, ConfigDict, Field

from app.control.errors import GoalRejected
from app.fields import Finite, Vector3
from app.server.api.deps import (
    ControlClient,
    ControllerDep,
    RunsDep,
    TokenChecked,
    WorldDep,
    websocket_token_ok,
)
from app.server.api.models import Accepted
from app.server.api.responses import PoseAccepted, PoseInputStatus, RunStarted
from app.server.errors import CONTROL, INVALID, UNAUTHORISED
from app.server.world_client import WorldClient
from app.world.drone_sim import DroneSimParams
from app.world.inputs import body_of, parse_pose, sample_from_json
from kinematics import PoseError

router = APIRouter(tags=["drone"])


class PoseBody(BaseModel):
    """One pose of the drone (or of a marker on the platform: ``body``): source time [s],
    world position [m], quaternion (w, x, y, z) body to world, optional world velocity
    [m/s] and body angular velocity [rad/s]."""

    model_config = ConfigDict(extra="forbid", strict=True)
    t: Finite
    position: Vector3
    quaternion: Annotated[list[Finite], Field(min_length=4, max_length=4)]
    velocity: Vector3 | None = None
    angular_velocity: Vector3 | None = None
    body: Literal["drone", "platform"] = Field(
        "drone",
        description="whose pose: drone (the robot's base, for hold-in-world) or platform (a "
        "motion-capture marker on the platform: a calibration run's measurement with "
        "measurement 'pose-input')",
    )


class HoldRequest(BaseModel):
    """Hold the tool at a world point ("world") or where it is now ("current")."""

    model_config = ConfigDict(extra="forbid", strict=True)
    position_m: Vector3 | None = None
    frame: Literal["world", "current"] = "world"
    source: Literal["external", "simulated"] = Field(
        "external", description="external: poses posted / streamed / MAVLink; simulated drone"
    )
    latency_compensation: bool = True
    heading_rad: float | None = Field(
        None,
        allow_inf_nan=False,
        description="with a wrist: the tool's world heading to keep [rad] (null: as it is now)",
    )


class HoldTestRequest(BaseModel):
    """The thesis's MAV compensation routine (ch. 6.2) on the simulated drone, as a run."""

    model_config = ConfigDict(extra="forbid", strict=True)
    duration_s: Annotated[float, Field(gt=0, le=600, allow_inf_nan=False)] = 20.0
    latency_compensation: bool = True
    seed: Annotated[int, Field(ge=0, lt=2**32)] = 0
    drift_m: Annotated[float, Field(ge=0, le=0.2, allow_inf_nan=False)] = DroneSimParams.drift_m
    tilt_deg: Annotated[float, Field(ge=0, le=20, allow_inf_nan=False)] = DroneSimParams.tilt_deg
    yaw_deg: Annotated[float, Field(ge=0, le=20, allow_inf_nan=False)] = DroneSimParams.yaw_deg
    gust_m: Annotated[float, Field(ge=0, le=0.2, allow_inf_nan=False)] = DroneSimParams.gust_m
    latency_s: Annotated[float, Field(ge=0, le=0.5, allow_inf_nan=False)] = DroneSimParams.latency_s
    rate_hz: Annotated[float, Field(gt=0, le=1000, allow_inf_nan=False)] = DroneSimParams.rate_hz

    def drone(self) -> DroneSimParams:
        fields = ("seed", "drift_m", "tilt_deg", "yaw_deg", "gust_m", "latency_s", "rate_hz")
        return DroneSimParams(**{name: getattr(self, name) for name in fields})


def _push(world: WorldClient, data: dict[str, Any]) -> dict[str, Any]:
    body_of(data)  # checked here: a bad body or field is the caller's 422, not the node's
    sample_from_json(data)
    return world.push(data)


@router.post("/mav/pose", response_model=PoseAccepted, responses={**UNAUTHORISED, **INVALID})
def post_pose(body: PoseBody, world: WorldDep, _: TokenChecked) -> dict[str, Any]:
    """One pose sample of the drone (or, with ``"body": "platform"``, of a marker on the
    platform); out-of-order, duplicate or jumping samples are dropped (accepted=false)."""
    return _push(world, body.model_dump())


@router.get("/mav/pose", response_model=PoseInputStatus, responses=INVALID)
def get_pose_status(
    world: WorldDep, body: Literal["drone", "platform"] = "drone"
) -> dict[str, Any]:
    """The pose input's health for ``body`` (the drone's by default, or the platform
    marker's): state (ok/stale/lost/none), age, rate, counters (and the UDP input's
    refused datagrams), and ``sources``: each pose source, what it accepts (open, token,
    trusted, signed, refused), whether its listener is alive, its counters and last
    error."""
    return world.pose_status(body)


@router.websocket("/mav/pose")
async def stream_poses(websocket: WebSocket, world: WorldDep) -> None:
    """A stream of pose JSON objects (same fields as POST, ``body`` included), one per text
    frame. Every bad frame (binary, not JSON, nested too deep, a number beyond a float, a
    bad field or body) is answered ``{"error": "..."}`` and the stream goes on."""
    if not websocket_token_ok(websocket):
        await websocket.close(code=1008, reason="missing or wrong token (?token=)")
        return
    await websocket.accept()
    while True:
        message = await websocket.receive()
        if message["type"] == "websocket.disconnect":
            return
        text = message.get("text")
        try:
            if text is None:
                raise PoseError("a pose is a JSON text frame, got a binary frame")
            await asyncio.to_thread(_push, world, parse_pose(text))
        except (ValueError, KeyError, TypeError, PoseError) as exc:
            await websocket.send_json({"error": str(exc)})


@router.post("/hold", response_model=Accepted, responses=CONTROL)
async def post_hold(
    body: HoldRequest, world: WorldDep, controller: ControllerDep, _: ControlClient
) -> Accepted:
    """Start mode hold-world: the tool stays at a world point while the drone drifts."""
    if body.frame == "world" and body.position_m is None:
        raise GoalRejected("position_m: required with frame 'world'")
    goal = None if body.frame == "current" else np.asarray(body.position_m)
    simulated = DroneSimParams() if body.source == "simulated" else None
    hold = world.hold(goal, simulated, body.latency_compensation, body.heading_rad)
    model = controller.model  # the hold is checked on it (refused if it changes meanwhile)
    # the hold mode blends in from wherever the robot is: no start point to check
    started = controller.run_source(hold, np.zeros(3), tolerance_m=math.inf, model=model)
    answer = await asyncio.wait_for(asyncio.wrap_future(started), 2.0)
    return Accepted(result={"goal_world_m": answer["goal_world_m"]})


@router.post("/tests/hold", response_model=RunStarted, responses=CONTROL)
async def post_hold_test(body: HoldTestRequest, world: WorldDep, runs: RunsDep, _: ControlClient):
    """Hold the current tool position in the world under a simulated drifting drone, as a run
    with world-frame stats (stats.world.{x,y,z}) and the time the goal spent outside."""
    model = runs.controller.model  # the hold is checked on it (refused if it changes)
    hold = world.hold(None, body.drone(), body.latency_compensation, duration_s=body.duration_s)
    params = {**body.model_dump(), "drone": asdict(body.drone())}
    run = await asyncio.to_thread(runs.start_source, "hold", params, hold, model)
    return {"run_id": run.run_id}

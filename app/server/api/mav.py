"""Drone side of the API: pose input (HTTP, WebSocket), hold-in-world, the hold test."""

from __future__ import annotations

import asyncio
import math
from dataclasses import asdict
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, Header, WebSocket
from pydantic import BaseModel, ConfigDict, Field

from app.control.errors import GoalRejected, MotionRefused
from app.fields import Finite, Vector3
from app.server.api.deps import (
    AuthorityDep,
    ControlClient,
    ControllerDep,
    RunsDep,
    SettingsDep,
    TokenChecked,
    WorldDep,
    websocket_token_ok,
)
from app.server.api.models import Accepted
from app.server.api.responses import PoseAccepted, PoseInputStatus, RunStarted
from app.server.errors import CONTROL, INVALID, UNAUTHORISED
from app.server.world_client import WorldClient
from app.world.drone_feed import feed_of, start_feed, stop_feed
from app.world.drone_sim import DroneSimParams, SimulatedDrone
from app.world.inputs import body_of, parse_pose, sample_from_json
from kinematics import Pose, PoseError

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


class DroneProfile(BaseModel):
    """A simulated drone's drift profile (app/world/drone_sim.py): SI, degrees for angles."""

    model_config = ConfigDict(extra="forbid", strict=True)
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


class SimulatedDroneRequest(DroneProfile):
    """Start (``running`` true, with its drift profile) or stop the simulated drone that
    feeds the pose input like a motion-capture stream."""

    running: bool
    rate_hz: Annotated[float, Field(gt=0, le=200, allow_inf_nan=False)] = DroneSimParams.rate_hz


class SimulatedDroneOut(BaseModel):
    """The simulated drone feeding the pose input: running, its profile (SI), poses sent."""

    running: bool
    params: dict[str, Any] | None = None
    sent: int = 0
    last_error: str | None = None


class PoseView(PoseInputStatus):
    """GET /api/mav/pose: the input's health, its latest pose and the simulated drone."""

    tool_world_m: list[float] | None = Field(
        None,
        description="the tool tip in the world [m] through the latest pose and the mount, "
        "the tip as measured now (null: no pose or no measurement)",
    )
    mount_position_m: list[float] = Field(description="[world] the base in the drone body [m]")
    mount_quaternion: list[float] = Field(description="[world] the base's attitude in the body")
    simulated: SimulatedDroneOut = Field(description="the simulated drone (POST /mav/simulated)")


class HoldTestRequest(DroneProfile):
    """A hold in the world as a run: the thesis's MAV compensation routine (ch. 6.2) on the
    simulated drone (source "simulated": the drone lives in the loop and moves the twin's
    base), or on the pose input (source "external": motion capture, MAVLink, the simulated
    drone's feed), at a world goal (``position_m``; null: where the tool is); the simulated
    drone's profile as ``DroneProfile``'s fields."""

    model_config = ConfigDict(extra="forbid", strict=True)
    duration_s: Annotated[float, Field(gt=0, le=600, allow_inf_nan=False)] = 20.0
    position_m: Vector3 | None = Field(None, description="the tip's world goal [m]; null: here")
    source: Literal["simulated", "external"] = "simulated"
    heading_rad: float | None = Field(
        None, allow_inf_nan=False, description="with a wrist: the tool's world heading [rad]"
    )
    latency_compensation: bool = True


def _push(world: WorldClient, data: dict[str, Any], source: str) -> dict[str, Any]:
    data = {**data, "source": source}  # the input it came by, never the client's say
    body_of(data)  # checked here: a bad body or field is the caller's 422, not the node's
    sample_from_json(data)
    return world.push(data)


@router.post("/mav/pose", response_model=PoseAccepted, responses={**UNAUTHORISED, **INVALID})
def post_pose(body: PoseBody, world: WorldDep, _: TokenChecked) -> dict[str, Any]:
    """One pose sample of the drone (or, with ``"body": "platform"``, of a marker on the
    platform); out-of-order, duplicate or jumping samples are dropped (accepted=false)."""
    return _push(world, body.model_dump(), "http")


def _simulated(world: WorldClient) -> dict[str, Any]:
    feed = feed_of(world)
    return {"running": False} if feed is None else feed.status()


@router.get("/mav/pose", response_model=PoseView, responses=INVALID)
def get_pose_status(
    world: WorldDep,
    settings: SettingsDep,
    controller: ControllerDep,
    body: Literal["drone", "platform"] = "drone",
) -> dict[str, Any]:
    """The pose input's health for ``body`` (the drone's by default, or the platform
    marker's): state (ok/stale/lost/none), age, rate, counters (and the UDP input's
    refused datagrams), ``sources``: each pose source, what it accepts (open, token,
    trusted, signed, refused), whether its listener is alive, its counters and last
    error; the latest sample (``source``, ``position_m`` [m], ``quaternion``), the mount
    (the base in the drone body), the tool tip in the world through them
    (``tool_world_m``) and the simulated drone's feed (``simulated``)."""
    status = world.pose_status(body)
    mount = Pose.from_arrays(settings.world.mount_position_m, settings.world.mount_quaternion)
    tip = np.asarray(controller.snapshot().point_measured_m, dtype=float)
    tool = None
    if status.get("position_m") is not None and np.isfinite(tip).all():
        drone = Pose.from_arrays(status["position_m"], status["quaternion"])
        tool = (drone @ mount).apply(tip).tolist()
    return status | {
        "tool_world_m": tool,
        "mount_position_m": list(settings.world.mount_position_m),
        "mount_quaternion": list(settings.world.mount_quaternion),
        "simulated": _simulated(world),
    }


@router.post("/mav/simulated", response_model=SimulatedDroneOut, responses={**CONTROL, **INVALID})
def post_simulated_drone(
    body: SimulatedDroneRequest,
    world: WorldDep,
    runs: RunsDep,  # not ControllerDep: stopping the drone must work with the robot offline
    authority: AuthorityDep,
    _: ControlClient,
    x_lease: Annotated[str | None, Header(description="the lease it runs under")] = None,
) -> dict[str, Any]:
    """Start (``running`` true) the simulated drone with its drift profile, feeding the
    pose input at ``rate_hz`` like a motion-capture stream (``GET /api/mav/pose`` source
    "simulated"; a hold with source "external" follows it), or stop it (the pose then goes
    stale, then lost: a hold on it freezes, then faults). Needs the lease, and flies only
    while that lease is the current one (given back or taken over: it stops). Refused
    (409) while another source's pose is fresh (it would stand in for a live input) or
    while a hold in the world runs (it would move the tool after a drone that is not
    there). Moves nothing by itself."""
    if not body.running:
        stop_feed(world)
        return _simulated(world)
    if runs.controller.snapshot().mode == "hold-world":
        raise MotionRefused(
            "a hold in the world is running: stop it before starting the simulated drone "
            "(the hold would follow it)"
        )
    seen = world.pose_status("drone")
    if seen.get("state") == "ok" and seen.get("source") not in (None, "simulated"):
        raise MotionRefused(
            f"the drone's pose input is live from {seen['source']}: the simulated drone "
            "would stand in for it; stop that stream first"
        )
    return start_feed(world, body.drone(), allowed=lambda: authority.holds(x_lease)).status()


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
            await asyncio.to_thread(_push, world, parse_pose(text), "websocket")
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
    if goal is not None and simulated is not None:  # as /tests/hold: at the drone's start
        start = SimulatedDrone(simulated).true_state(0.0)[0]
        check_goal(start, goal, controller, "at the simulated drone's start")
    elif goal is not None:  # on the pose input: against its latest pose, where there is one
        seen = await asyncio.to_thread(world.pose_status, "drone")
        if seen.get("state") == "ok" and seen.get("position_m") is not None:
            drone = Pose.from_arrays(seen["position_m"], seen["quaternion"])
            check_goal(drone, goal, controller, "at the drone's pose now")
    hold = world.hold(goal, simulated, body.latency_compensation, body.heading_rad)
    model = controller.model  # the hold is checked on it (refused if it changes meanwhile)
    # the hold mode blends in from wherever the robot is: no start point to check
    started = controller.run_source(hold, np.zeros(3), tolerance_m=math.inf, model=model)
    answer = await asyncio.wait_for(asyncio.wrap_future(started), 2.0)
    return Accepted(result={"goal_world_m": answer["goal_world_m"]})


def check_external(seen: dict[str, Any], goal: np.ndarray | None, controller: Any) -> None:
    """Refuse a hold on the pose input unless its latest pose is fresh (MotionRefused,
    409) and, for a world ``goal`` [m], unless the goal is inside the workspace through
    that pose and the mount (GoalRejected naming ``position_m``, 422)."""
    if seen.get("state") != "ok" or seen.get("position_m") is None:
        age = seen.get("age_s")
        told = "" if age is None else f", {age * 1e3:.0f} ms old"
        raise MotionRefused(
            f"source: the drone's pose input is {seen.get('state', 'none')}{told}; "
            "a hold on it needs a fresh pose (start the simulated drone or a pose stream)"
        )
    if goal is not None:
        drone = Pose.from_arrays(seen["position_m"], seen["quaternion"])
        check_goal(drone, goal, controller, "at the drone's pose now")


def check_goal(drone: Pose, goal: np.ndarray, controller: Any, when: str) -> None:
    """GoalRejected (422, naming ``position_m``) unless the world ``goal`` [m] is inside
    the workspace through the drone's pose ``drone`` and the mount (``when``: which pose)."""
    world = controller.settings.world
    mount = Pose.from_arrays(world.mount_position_m, world.mount_quaternion)
    with np.errstate(all="ignore"):  # a goal light-years away: inf or nan, refused below
        goal_base = (drone @ mount).apply_inverse(goal)
    if not np.isfinite(goal_base).all() or not controller.gate.inside(goal_base, 0.0):
        raise GoalRejected(
            f"position_m: outside the workspace {when} "
            f"(in the base frame [{', '.join(f'{v:.4f}' for v in goal_base)}] m)"
        )


@router.post("/tests/hold", response_model=RunStarted, responses=CONTROL)
async def post_hold_test(body: HoldTestRequest, world: WorldDep, runs: RunsDep, _: ControlClient):
    """Hold the tool in the world as a run, with world-frame stats (stats.world.{x,y,z}) and
    the time the goal spent outside: at ``position_m`` (null: where it is), on the simulated
    drone (source "simulated") or the pose input (source "external": refused with 409
    unless its pose is fresh, and a goal outside the workspace at the drone's pose now is
    a 422 naming ``position_m``)."""
    model = runs.controller.model  # the hold is checked on it (refused if it changes)
    goal = None if body.position_m is None else np.asarray(body.position_m, dtype=float)
    simulated = body.drone() if body.source == "simulated" else None
    if simulated is None:
        seen = await asyncio.to_thread(world.pose_status, "drone")
        check_external(seen, goal, runs.controller)
    elif goal is not None:  # the simulated drone starts at its pose at t = 0
        start = SimulatedDrone(simulated).true_state(0.0)[0]
        check_goal(start, goal, runs.controller, "at the simulated drone's start")
    hold = world.hold(
        goal, simulated, body.latency_compensation, body.heading_rad, duration_s=body.duration_s
    )
    if simulated is None:  # on the pose input: no simulated drone's profile to record
        profile = set(DroneProfile.model_fields)
        params = {**body.model_dump(exclude=profile), "drone": None}
    else:
        params = {**body.model_dump(), "drone": asdict(simulated)}
    run = await asyncio.to_thread(runs.start_source, "hold", params, hold, model)
    return {"run_id": run.run_id}

"""Hold-in-world at the robot node: the drone's pose inputs and the hold source.

The drone's odometry is onboard, beside the loop: the pose trackers (the drone's and a
platform marker's), the UDP and MAVLink pose listeners of the node's config, the
simulated drone (which moves the twin's base) and the hold source all live in the node
(app/world/service.py). A station pushes the poses it receives over HTTP or WebSocket
(op ``pose``), reads the trackers' status, and starts a hold (op ``hold``) with its goal
and options as data; the hold's world-frame figures and the drone's pose come back in
each snapshot's ``extra``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from app.control.controller import Controller
from app.control.errors import GoalRejected
from app.world.drone_sim import DroneSimParams
from app.world.hold import HoldSource
from app.world.inputs import body_of, sample_from_json
from app.world.service import WorldService

SOURCES = ("external", "simulated")


class NodeWorld:
    """The node's pose inputs and hold-in-world (ops ``pose``, ``pose_status``,
    ``pose_latest``, ``restart_inputs``, ``hold``)."""

    def __init__(self, controller: Controller) -> None:
        self.controller = controller
        self.service = WorldService(controller)

    def push(self, args: dict[str, Any]) -> dict[str, Any]:
        """One pose sample (the documented JSON, ``body`` included) into its tracker:
        whether it was kept, and the tracker's status."""
        data = args.get("pose")
        tracker = self.service.tracker_for(body_of(data))  # type: ignore[arg-type]
        accepted = tracker.push(sample_from_json(data))  # type: ignore[arg-type]
        return {"accepted": accepted, "input": tracker.status()}

    def status(self, args: dict[str, Any]) -> dict[str, Any]:
        """The tracker of ``body``'s status, the UDP input's refusals and every source."""
        service = self.service
        body = args.get("body", "drone")
        tracker = service.tracker_for(body)
        return tracker.status() | {"udp_errors": service.udp_errors(), "sources": service.sources()}

    def latest(self, args: dict[str, Any]) -> dict[str, Any]:
        """The latest sample of ``body``'s tracker: its position [m] (None: none yet) and
        the tracker's health (state, age [s]; None: no sample)."""
        tracker = self.service.tracker_for(args.get("body", "drone"))
        sample, _ = tracker.latest()
        state, age = tracker.health()
        return {
            "position_m": None if sample is None else np.asarray(sample.position_m).tolist(),
            "state": state,
            "age_s": None if math.isinf(age) else age,
        }

    def restart(self, args: dict[str, Any]) -> None:
        self.service.restart_inputs()

    def hold_source(self, args: dict[str, Any]) -> HoldSource:
        """The hold ``args`` ask for: ``goal_world_m`` (None: where the tool is now),
        ``source`` external or simulated (``drone``: the simulated drone's parameters),
        ``latency_compensation``, ``heading_rad`` (with a wrist) and ``duration_s`` (a
        timed hold, a run; None: until stopped). GoalRejected / ValueError name the field."""
        kind = args.get("source", "external")
        if kind not in SOURCES:
            raise ValueError(f"source: expected one of {SOURCES}, got {kind!r}")
        drone = None
        if kind == "simulated":
            try:
                drone = DroneSimParams(**(args.get("drone") or {}))
            except TypeError as exc:
                raise ValueError(f"drone: {exc}") from None
        goal = args.get("goal_world_m")
        if goal is not None:
            goal = np.asarray(goal, dtype=np.float64)
            if goal.shape != (3,) or not np.isfinite(goal).all():
                raise GoalRejected("goal_world_m: expected 3 finite numbers")
        heading = args.get("heading_rad")
        compensate = args.get("latency_compensation", True)
        if not isinstance(compensate, bool):
            raise ValueError("latency_compensation: expected true or false")
        provider = self.service.provider(drone)
        source = self.service.hold_source(goal, provider, compensate, heading)
        duration = args.get("duration_s")
        if duration is not None:
            if not (isinstance(duration, int | float) and math.isfinite(duration) and duration > 0):
                raise ValueError(f"duration_s: expected a positive number, got {duration!r}")
            source.duration_s = float(duration) + source.approach_s
        return source

    def close(self) -> None:
        self.service.close()

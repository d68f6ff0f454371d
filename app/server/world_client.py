"""Hold-in-world as the station sees it: the robot node's pose inputs and holds.

The pose trackers, the UDP and MAVLink listeners and the hold source are the node's
(app/robot/world.py); the station forwards the poses its API receives, reads the
trackers' status, and asks the node for holds. :class:`HoldRun` is the station's record
of a hold the node plays: what the run manager and the recorder follow (its id, time,
end), as :class:`~app.runs.source.TrajectorySource` is for a planned run.
"""

from __future__ import annotations

import math
from concurrent.futures import Future
from dataclasses import asdict
from typing import Any

import numpy as np

from app.control.sources import Progress
from app.link.client import RobotClient
from app.world.drone_sim import DroneSimParams

HOLD_MODE = "hold-world"
APPROACH_S = 1.0  # app/world/hold.py HoldSource.approach_s: the blend-in


class HoldRun:
    """A hold the node plays, as a run: ``args`` are the op's (goal, source, options);
    ``duration_s`` [s] the hold's length after its approach (None: until stopped)."""

    name = HOLD_MODE
    remote_op = "hold"

    def __init__(self, args: dict[str, Any], duration_s: float | None) -> None:
        self.args = {**args, "duration_s": duration_s}
        self.approach_s = APPROACH_S
        self.duration_s = None if duration_s is None else duration_s + APPROACH_S
        self.t_s = 0.0
        self.finished = False
        self.program_line: int | None = None
        self.source_id: str | None = None

    def remote_args(self) -> dict[str, Any]:
        return dict(self.args)

    def progress(self) -> Progress:
        t, total = self.t_s, self.duration_s if self.duration_s is not None else math.inf
        phase = "approach" if t < self.approach_s else "hold"
        return Progress.at(phase, t, self.approach_s, total - self.approach_s)


class _Tracker:
    """One of the node's pose trackers (``body``), as far as the station reads it."""

    def __init__(self, world: WorldClient, body: str) -> None:
        self.world, self.body = world, body

    def status(self) -> dict[str, Any]:
        return self.world.pose_status(self.body)

    def latest(self) -> tuple[Any, np.ndarray]:
        """(the latest sample, with its ``position_m``; None: none), zero velocity."""
        latest = self.world.pose_latest(self.body)
        position = latest.get("position_m")
        sample = None if position is None else _Sample(np.asarray(position, dtype=float))
        return sample, np.zeros(3)

    def health(self) -> tuple[str, float]:
        latest = self.world.pose_latest(self.body)
        age = latest.get("age_s")
        return str(latest.get("state", "none")), math.inf if age is None else float(age)


class _Sample:
    def __init__(self, position_m: np.ndarray) -> None:
        self.position_m = position_m


class WorldClient:
    """The station's handle on the node's pose inputs and holds (the routes' ``world``)."""

    def __init__(self, client: RobotClient) -> None:
        self.client = client
        self.tracker = _Tracker(self, "drone")
        self.platform = _Tracker(self, "platform")

    def _ask(self, op: str, args: dict[str, Any]) -> Any:
        return self.client.request(op, args).result(timeout=self.client.command_timeout_s + 1)

    def tracker_for(self, body: str) -> _Tracker:
        """The tracker of ``body`` ("drone" or "platform"); ValueError for another."""
        if body not in ("drone", "platform"):
            raise ValueError(f"body: {body!r} is not 'drone' or 'platform'")
        return self.tracker if body == "drone" else self.platform

    def push(self, pose: dict[str, Any]) -> dict[str, Any]:
        """One pose (the documented JSON, checked by the route) into the node's tracker:
        ``{"accepted", "input"}``."""
        return self._ask("pose", {"pose": pose})

    def pose_status(self, body: str = "drone") -> dict[str, Any]:
        """``body``'s tracker status, the UDP input's refusals (``udp_errors``) and every
        pose source (``sources``)."""
        return self._ask("pose_status", {"body": body})

    def pose_latest(self, body: str) -> dict[str, Any]:
        return self._ask("pose_latest", {"body": body})

    def restart_inputs(self) -> None:
        self._ask("restart_inputs", {})

    def hold(
        self,
        goal_world_m: np.ndarray | None,
        simulated: DroneSimParams | None,
        compensate: bool,
        heading_rad: float | None = None,
        duration_s: float | None = None,
    ) -> HoldRun:
        """A hold for the node to play (``run_source`` starts it): at ``goal_world_m``
        [m] (None: where the tool is), on the simulated drone ``simulated`` or the
        external poses, with latency compensation, keeping ``heading_rad`` with a wrist."""
        args = {
            "goal_world_m": None if goal_world_m is None else np.asarray(goal_world_m).tolist(),
            "source": "external" if simulated is None else "simulated",
            "drone": None if simulated is None else asdict(simulated),
            "latency_compensation": compensate,
            "heading_rad": heading_rad,
        }
        return HoldRun(args, duration_s)

    def start(self, hold: HoldRun) -> Future:
        """Start ``hold`` now (not as a recorded run): a Future of the node's answer
        (``goal_world_m``, ...)."""
        return self.client.run_source(hold, np.zeros(3), math.inf)

    def close(self) -> None:
        """Nothing of the station's to close: the inputs are the node's."""

"""The robot model the controller uses: its kinematics and the gate built on them.

One owner: the controller (``Controller.model``, inside its ``CommandContext``). Everything
that computes with the robot reads it from there when it computes, never a copy kept from
the start: the tick's FK and IK, the gate (workspace, margin, ceiling, joint limits,
singularity), jog clamps and their nearest points, hold-in-world, runs' and programs'
checks, the server's workspace views and the 3D scene.

The model starts as the config's (``[robot]``, with ``[robot.legs]`` when given: a per-leg
robot). A geometry calibration's apply replaces it (``Controller.use_model``) in the
control thread, between two ticks, only while the arm rests. ``version`` counts the
replacements: a goal or a run checked against one model is refused (409) if another is in
use by the time it would start, and a calibration fitted against an older model is not
applied.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from app.control.gate import Gate
from kinematics import LinearDelta, PerLegRotaryDelta, RotaryDelta

Robot = RotaryDelta | PerLegRotaryDelta | LinearDelta


@dataclass(frozen=True)
class RobotModel:
    """The gate (with its robot) in use, how many times it was replaced, and from where.

    gate: the checks and limits on ``gate.robot``; version: 0 for the config's model, +1
    per replacement; origin: where the model came from ("config", "calibration <run_id>").
    """

    gate: Gate
    version: int = 0
    origin: str = "config"

    @property
    def robot(self) -> Robot:
        return self.gate.robot

    def replaced(self, robot: Robot, origin: str) -> RobotModel:
        """The same limits on ``robot``, as the next version. Builds the new gate, which
        pays its workspace's first projection (tens to hundreds of ms): call it outside the
        control thread."""
        return RobotModel(replace(self.gate, robot=robot), self.version + 1, origin)

    def describe(self) -> dict[str, Any]:
        """The model for the API: kind, version, origin and, for a rotary Delta, each leg's
        L, l, R, r [m] (equal for a symmetric one) and base angle [rad]."""
        robot = self.robot
        kind = {RotaryDelta: "symmetric", PerLegRotaryDelta: "per-leg"}.get(type(robot), "linear")
        body: dict[str, Any] = {"kind": kind, "version": self.version, "origin": self.origin}
        if isinstance(robot, RotaryDelta | PerLegRotaryDelta):
            body |= {f"{name}_m": list(leg_values(robot, name)) for name in ("L", "l", "R", "r")}
            legs = (
                robot
                if isinstance(robot, PerLegRotaryDelta)
                else PerLegRotaryDelta.from_symmetric(robot)
            )
            body["angles_rad"] = list(legs.angles_rad)
        return body


def leg_values(robot: Robot, name: str) -> tuple[float, float, float]:
    """One length of each leg [m] (``name`` one of L, l, R, r); a symmetric robot's three
    are its one value."""
    value = getattr(robot, name)
    return tuple(value) if isinstance(value, tuple) else (float(value),) * 3  # type: ignore[return-value]


def reach_m(robot: Robot) -> float:
    """A length [m] beyond which no leg reaches, from the base centre: the largest R + L +
    l (a linear Delta has no L)."""
    if isinstance(robot, LinearDelta):
        return float(robot.R + robot.l)
    return max(
        sum(values) for values in zip(*(leg_values(robot, n) for n in ("R", "L", "l")), strict=True)
    )


def dynamics_robot(robot: Robot) -> RotaryDelta | LinearDelta:
    """The robot the dynamics (gravity offset, the programs' torque check) use: a per-leg
    robot's symmetric one of the legs' mean L, l, R, r (``PerLegRotaryDelta.nominal``; the
    dynamics model equal legs, and a leg a millimetre off changes a torque by well under
    1 %), any other robot itself."""
    return robot.nominal() if isinstance(robot, PerLegRotaryDelta) else robot

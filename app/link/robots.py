"""A robot's kinematics as data on the link (a calibrated model sent to the robot node)."""

from __future__ import annotations

import dataclasses
from typing import Any

from app.control.model import Robot
from kinematics import LinearDelta, PerLegRotaryDelta, RotaryDelta
from kinematics.errors import DeltaError

KINDS: dict[str, type] = {
    "rotary": RotaryDelta,
    "per-leg": PerLegRotaryDelta,
    "linear": LinearDelta,
}


def robot_data(robot: Robot) -> dict[str, Any]:
    """``{"kind": ..., <the robot's fields>}``: what :func:`robot_of` builds it again from."""
    kind = next(name for name, cls in KINDS.items() if type(robot) is cls)
    fields = {f.name: getattr(robot, f.name) for f in dataclasses.fields(robot) if f.init}
    return {"kind": kind, **{k: _plain(v) for k, v in fields.items()}}


def _plain(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return float(value) if isinstance(value, int | float) else value


def robot_of(data: Any) -> Robot:
    """The robot of :func:`robot_data`'s form; ValueError naming what is wrong."""
    if not isinstance(data, dict) or data.get("kind") not in KINDS:
        raise ValueError(f"robot.kind: expected one of {sorted(KINDS)}")
    cls = KINDS[data["kind"]]
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items() if k != "kind"}
    unknown = sorted(set(values) - names)
    if unknown:
        raise ValueError(f"robot.{unknown[0]}: not a field of a {data['kind']} Delta")
    try:
        return cls(**values)
    except (DeltaError, TypeError, ValueError) as exc:
        raise ValueError(f"robot: {exc}") from None

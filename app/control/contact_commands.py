"""The contact commands (touch, press) as functions of the loop's state, as the others are.

Checked before anything moves: the force asked within ``contact.force_limit_n``, the
travel's end inside the workspace, a force estimate on this robot. They run in the
control thread (app/control/controller.py queues them).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from app.config import ContactSettings
from app.control.commands import CommandContext, begin_motion, require_motion, start_point
from app.control.errors import GoalRejected, MotionRefused
from app.control.loop_state import LoopState
from app.control.press import PressSource
from app.control.sources import GoalSource
from app.control.touch import TouchSource, unit_direction

#: A touch's speed bounds [m/s]: below the least, a touch of its longest travel (0.3 m)
#: would hold the robot for more than 50 min (1e-320 m/s: for ever).
MIN_TOUCH_SPEED_M_S = 1e-4
MAX_TOUCH_SPEED_M_S = 0.1


def check_touch_speed(speed_m_s: Any, name: str = "speed_m_s") -> float:
    """A touch's speed [m/s]: finite, within MIN_TOUCH_SPEED_M_S .. MAX_TOUCH_SPEED_M_S
    (ValueError naming ``name`` otherwise)."""
    speed = _positive(speed_m_s, name, MAX_TOUCH_SPEED_M_S, " m/s")
    if speed < MIN_TOUCH_SPEED_M_S:
        raise ValueError(f"{name}: {speed:g} m/s is below the least of {MIN_TOUCH_SPEED_M_S:g} m/s")
    return speed


AT_REST_RAD_S = 0.05  # every leg slower than this: the arm rests (its force is no inertia)


def _positive(value: Any, name: str, most: float | None = None, unit: str = "") -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    if value <= 0:
        raise ValueError(f"{name}: must be > 0, got {value!r}")
    if most is not None and value > most:
        raise ValueError(f"{name}: {value:g}{unit} is over the limit of {most:g}{unit}")
    return float(value)


def check_force(force_n: Any, settings: ContactSettings, name: str = "force_n") -> float:
    """A force a command asks for [N]: finite, > 0 and within ``contact.force_limit_n``
    (ValueError naming ``name`` otherwise)."""
    return _positive(force_n, name, settings.force_limit_n, " N")


def _require_estimate(state: LoopState) -> None:
    monitor = state.contact_monitor
    if monitor is None or monitor.estimator is None:
        raise MotionRefused(
            "no contact force estimate on this robot (it needs a rotary Delta whose servos "
            "carry the arm: the twin or real servos, and [contact] estimate on)"
        )
    if not state.contact.valid:
        raise MotionRefused(f"the contact force estimate is not valid now: {state.contact.reason}")


def touch(
    state: LoopState,
    ctx: CommandContext,
    settings: ContactSettings,
    direction: Any,
    speed_m_s: Any = None,
    force_n: Any = None,
    max_travel_m: Any = None,
    retract_m: Any = 0.0,
) -> dict[str, Any]:
    """Start a touch (app/control/touch.py) from where the tip is commanded: along
    ``direction`` (3,) (base frame) at ``speed_m_s`` [m/s] until ``force_n`` [N], within
    ``max_travel_m`` [m], then back ``retract_m`` [m]; None takes the ``[contact]`` default.
    Returns {"source_id", "start_m", "end_m"}. ValueError / GoalRejected naming the field,
    MotionRefused when the robot may not move or has no force estimate."""
    d = unit_direction(direction)
    speed = check_touch_speed(settings.touch_speed_m_s if speed_m_s is None else speed_m_s)
    force = check_force(settings.touch_force_n if force_n is None else force_n, settings)
    if force <= settings.detect_force_n:
        raise ValueError(
            f"force_n: {force:g} N is not above the contact threshold "
            f"{settings.detect_force_n:g} N (contact.detect_force_n)"
        )
    travel = _positive(
        settings.touch_max_travel_m if max_travel_m is None else max_travel_m,
        "max_travel_m",
        0.3,
        " m",
    )
    retract = float(retract_m or 0.0)
    if not (math.isfinite(retract) and 0.0 <= retract <= travel):
        raise ValueError(f"retract_m: must be within 0 .. max_travel_m ({travel:g} m)")
    require_motion(state)
    _require_estimate(state)
    along = float(np.dot(state.contact.force_n, d))
    still = state.joints is not None and bool(
        (np.abs(state.joints.velocity_rad_s[:3]) < AT_REST_RAD_S).all()
    )
    if still and along >= settings.detect_force_n:  # (moving, it may be the arm's inertia)
        raise MotionRefused(
            f"the tip already pushes {along:.1f} N along the direction: it is in contact "
            "(a touch tares the force it starts with); move away from the surface first"
        )
    start = start_point(state).copy()
    end = start + d * travel
    phi = state.phi_rad
    if not ctx.gate.inside(end, phi):
        raise GoalRejected(
            "max_travel_m: the touch's end "
            f"({', '.join(f'{v * 1e3:.1f}' for v in end)}) mm is outside the workspace"
        )
    source = TouchSource(start, d, speed, force, settings.detect_force_n, travel, retract)
    begin_motion(state, source)
    state.touch = source.touch_result
    return {"source_id": source.source_id, "start_m": start.tolist(), "end_m": end.tolist()}


def press(
    state: LoopState,
    ctx: CommandContext,
    settings: ContactSettings,
    direction: Any,
    force_n: Any,
    inner: GoalSource | None = None,
    frame: str = "base",
    duration_s: Any = None,
) -> dict[str, Any]:
    """Start a compliant press (app/control/press.py): ``force_n`` [N] along ``direction``
    (3,) in ``frame`` from where the tip is commanded (``inner`` None), or on top of
    ``inner`` (a hold in the world). Returns {"source_id"}. Errors as :func:`touch`."""
    force = check_force(force_n, settings)
    duration = None if duration_s is None else _positive(duration_s, "duration_s", 3600.0, " s")
    require_motion(state)
    _require_estimate(state)
    start = start_point(state).copy()
    if inner is None and frame == "base":
        d = unit_direction(direction)
        reach = start + d * settings.press_travel_m
        if not ctx.gate.inside(reach, state.phi_rad):
            raise GoalRejected(
                "direction: the press may move the tip "
                f"{settings.press_travel_m * 1e3:.0f} mm along it (contact.press_travel_m), "
                "out of the workspace from here"
            )
    source = PressSource(
        inner,
        start,
        direction,
        force,
        settings.admittance_m_per_n_s,
        settings.press_travel_m,
        frame=frame,
        duration_s=duration,
    )
    begin_motion(state, source)
    return {"source_id": source.source_id, "start_m": np.asarray(start).tolist()}

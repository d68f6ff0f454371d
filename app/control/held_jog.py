"""Hold-to-move: a jog that moves only while the operator holds it (a dead man's switch).

A client (the page's keys, pad and gamepad) sends the jog's velocity again and again while
a key or button is held: ``POST /api/jog {"velocity_m_s": [...]}`` about every 50 ms. Each
one is a heartbeat: it renews a deadline in the loop's state (``hold_deadline_s``, loop
time). The tick checks it before the jog advances; past it (a frozen tab, a closed lid, a
lost link) the jog brakes to a jerk-limited stop where it is. A zero velocity stops it at
once. While held, each tick aims the jog a little ahead of where its path is, along the
velocity and clamped onto what the gate passes, so the robot cruises at the asked speed
and stops at the workspace boundary rather than past it.

Functions of the loop's state, like app/control/commands.py; the controller runs them in
the control thread only, with ``now_s`` its loop clock.
"""

from __future__ import annotations

import math

import numpy as np

from app.control.commands import CommandContext, jog_source
from app.control.errors import GoalRejected
from app.control.loop_state import LoopState
from app.control.sources import JogSource

LOOKAHEAD_TICKS = 4  # aim this many ticks past the braking distance


def hold_jog(state: LoopState, ctx: CommandContext, velocity_m_s: np.ndarray, now_s: float) -> dict:
    """Start or renew a held jog at ``velocity_m_s`` [m/s] (capped at the jog speed);
    zero stops it. GoalRejected if the robot cannot move from where it is. Returns the
    velocity used, how long it holds without another heartbeat [s] and the loop time [s]."""
    velocity = np.asarray(velocity_m_s, dtype=np.float64)
    speed = math.hypot(*velocity)  # no overflow: |[1e200, 0, 0]| is 1e200, not inf
    if speed == 0.0:
        release(state, None)
        return {"velocity_m_s": [0.0, 0.0, 0.0], "hold_s": 0.0, "time_s": now_s}
    if speed > ctx.jog_limits.velocity:
        velocity = velocity * (ctx.jog_limits.velocity / speed)
    source = jog_source(state, ctx, renewal=state.hold_deadline_s is not None)
    source.set_speed(np.abs(velocity))
    state.hold_velocity_m_s = velocity
    try:
        _aim(state, ctx, source)  # refuses (422) a jog that cannot start, before it is held
    except GoalRejected:
        state.hold_velocity_m_s = None
        raise
    state.hold_deadline_s = now_s + ctx.hold_timeout_s
    return {"velocity_m_s": velocity.tolist(), "hold_s": ctx.hold_timeout_s, "time_s": now_s}


def tick(state: LoopState, ctx: CommandContext, now_s: float) -> None:
    """Each tick, before the source advances: stop a held jog whose heartbeat is late,
    else aim it ahead along its velocity."""
    if state.hold_deadline_s is None:
        return
    source = state.source
    if not isinstance(source, JogSource):  # replaced by a move or a run
        state.hold_deadline_s = state.hold_velocity_m_s = None
        return
    if now_s > state.hold_deadline_s:
        release(state, f"jog stopped: no heartbeat for {ctx.hold_timeout_s:g} s")
        return
    try:
        _aim(state, ctx, source)
    except GoalRejected as exc:
        release(state, f"jog stopped: {exc}")


def release(state: LoopState, why: str | None) -> None:
    """End the held jog: it brakes to a stop where it is; ``why`` goes to the notice."""
    state.hold_deadline_s = state.hold_velocity_m_s = None
    if isinstance(state.source, JogSource):
        state.source.brake()
    if why is not None:
        state.notice = why


def _aim(state: LoopState, ctx: CommandContext, source: JogSource) -> None:
    """Target a point ahead of the path along the held velocity, past where braking from
    the asked speed would end, clamped onto what the gate passes."""
    velocity = state.hold_velocity_m_s
    assert velocity is not None
    speed = float(np.linalg.norm(velocity))
    limits = ctx.jog_limits
    if speed >= limits.acceleration**2 / limits.jerk:
        braking_s = speed / limits.acceleration + limits.acceleration / limits.jerk
    else:
        braking_s = 2.0 * float(np.sqrt(speed / limits.jerk))
    ahead_m = velocity * (braking_s + LOOKAHEAD_TICKS * ctx.period_s)
    here = source.commanded_m
    target = ctx.gate.clamp_towards(here, here + ahead_m, state.reference_rad, state.phi_rad)
    source.set_target(target)
    state.goal_m = target

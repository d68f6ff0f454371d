"""Snapshots to JSON-ready dicts: NaN becomes null, arrays become lists.

What the loop reports comes from its published :class:`~app.control.state.Snapshot`
alone (never from live controller attributes), so a status or a telemetry message is one
tick's view, whichever thread or process builds it.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import Any

import numpy as np

from app.control.loop_health import classify
from app.control.state import Snapshot
from app.server.estop import EstopReceipt
from app.world.heading import wrap


def floats(values: Any) -> list[float | None]:
    """A vector as a list, with null where the value is unknown (NaN)."""
    return [None if not math.isfinite(v) else float(v) for v in np.asarray(values).tolist()]


def status(
    snap: Snapshot, estop: EstopReceipt | None = None, pose: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Everything GET /api/status reports: the loop's snapshot ``snap``, with the station's
    record of the last e-stop press (``estop``; None: none) and the pose input's status
    (``pose``, app/world/poses.py; None: no pose input)."""
    estop = estop or EstopReceipt()
    return {
        "mode": snap.mode,
        "backend": snap.info.backend,
        "backend_description": snap.info.backend_description,
        "torque": snap.torque,
        "estopped": snap.estopped,
        "estop_received_unix_s": estop.received_unix_s,
        "estop_arrivals_unix_s": dict(estop.arrivals_unix_s),
        "faults": [f.as_dict() for f in snap.faults],
        "faults_dropped": snap.faults_dropped,
        "warning": snap.warning,
        "notice": snap.notice,
        "time_s": snap.time_s,
        "joints": {
            "servo_ids": list(snap.info.servo_ids),
            "position_rad": floats(snap.joints_measured_rad),
            "commanded_rad": floats(snap.joints_commanded_rad),
            **{name: floats(values) for name, values in snap.readings.items()},
            "moving": list(snap.moving),
            "hardware_errors": [list(e) for e in snap.hardware_errors],
            "torque_enabled": list(snap.torque_enabled),
        },
        "ee": {
            "position_m": floats(snap.point_measured_m),
            "platform_m": floats(snap.platform_measured_m),
            "phi_rad": snap.tool_phi_rad,
            "commanded_m": floats(snap.point_commanded_m),
            "error_m": floats(snap.shown_error_m),
            "external_m": floats(snap.external_m),
        },
        "goal": {"position_m": floats(snap.goal_m), "phi_rad": goal_phi(snap)},
        "loop": loop_timing(snap),
        "bus": {"missed_reads": snap.missed_reads, **asdict(snap.bus_stats)},
        "pose": pose,
        "phase": snap.phase,
        "gains": {
            str(sid): g.as_dict() for sid, g in zip(snap.info.servo_ids, snap.gains, strict=True)
        },
        "servo_mode": snap.servo_mode,
        "goal_current_a": [float(c) for c in snap.goal_current_a],
        "servos": servos(snap),
        "wrist_servo": wrist_servo(snap),
        "contact": contact(snap),
    }


def contact(snap: Snapshot) -> dict[str, Any]:
    """The tip's contact force this tick (app/control/contact.py): ``force_n`` the force
    the tip applies, base frame [N], ``std_n`` its 1-sigma error [N], ``valid``, ``reason``
    (why not valid), ``magnitude_n`` [N]."""
    reading = snap.contact
    return {
        "force_n": floats(reading.force_n),
        "std_n": floats(reading.std_n),
        "magnitude_n": _maybe(reading.magnitude_n),
        "valid": reading.valid,
        "reason": reading.reason,
    }


def touch(snap: Snapshot) -> dict[str, Any] | None:
    """The last touch (app/control/touch.py): outcome, contact point [m], force [N], peak
    force along its direction [N], travel [m], direction, id; None: none yet."""
    result = snap.touch
    if result is None:
        return None
    return {
        "outcome": result.outcome,
        "contact_point_m": floats(result.contact_point_m),
        "force_n": floats(result.force_n),
        "peak_force_n": _maybe(result.peak_force_n),
        "travel_m": _maybe(result.travel_m),
        "direction": floats(result.direction),
        "source_id": result.source_id,
        "joints_at_contact_rad": floats(result.joints_at_contact_rad),
        "reason": result.reason,
    }


def servos(snap: Snapshot) -> list[dict[str, Any]]:
    """Every servo on the bus in bus order, with its role: the legs (``joint`` 1..3, as
    ``joints.servo_ids`` lists them), then the wrist's when one is fitted (joint null)."""
    legs = [{"id": sid, "role": "leg", "joint": k + 1} for k, sid in enumerate(snap.info.servo_ids)]
    wrist = snap.info.wrist_servo_id
    return legs + ([] if wrist is None else [{"id": wrist, "role": "wrist", "joint": None}])


def _maybe(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def wrist_servo(snap: Snapshot) -> dict[str, Any] | None:
    """The wrist's servo as last read (null figures before its first read): phi measured
    and commanded [rad] and its readings; None without a wrist."""
    sid = snap.info.wrist_servo_id
    if sid is None:
        return None
    read = snap.wrist_servo
    figure = (lambda name: _maybe(getattr(read, name))) if read is not None else (lambda _: None)
    return {
        "servo_id": sid,
        "position_rad": _maybe(snap.phi_measured_rad),
        "commanded_rad": _maybe(snap.phi_commanded_rad),
        **{name: figure(name) for name in ("velocity_rad_s", "current_a", "voltage_v")},
        "temperature_c": figure("temperature_c"),
        "pwm": figure("pwm"),
        "hardware_errors": list(read.hardware_errors) if read is not None else [],
        "torque_enabled": read.torque_enabled if read is not None else None,
    }


def goal_phi(snap: Snapshot) -> float | None:
    """The wrist's goal [rad]: its goal, else (holding) what is commanded; None without a
    wrist (both NaN) or without a setpoint (torque off: nothing holds it)."""
    if not snap.torque:
        return None
    for phi in (snap.phi_goal_rad, snap.phi_commanded_rad):
        if math.isfinite(phi):
            return float(phi)
    return None


def loop_timing(snap: Snapshot) -> dict[str, Any]:
    """The loop's timing as of ``snap``: since start and over its last 10 s, with the
    health light (app/control/loop_health.py)."""
    total, window = snap.loop_total, snap.loop_window
    return {
        "target_hz": total.target_hz,
        "measured_hz": window.measured_hz,
        "period_mean_ms": window.period_mean_ms,
        "jitter_p50_ms": window.jitter_p50_ms,
        "jitter_p99_ms": window.jitter_p99_ms,
        "worst_ms": window.worst_ms,
        "overruns": total.overruns,
        "ticks": total.ticks,
        "longest_gap_ms": window.longest_gap_ms,
        "since_start": asdict(total),
        "last_10s": asdict(window),
        "health": asdict(classify(window)),
    }


def telemetry(snap: Snapshot) -> dict[str, Any]:
    """One telemetry WebSocket message, from the tick's snapshot ``snap``."""
    window = snap.loop_window
    return {
        "t": snap.time_s,
        "tick": snap.tick,
        "mode": snap.mode,
        "goal_m": floats(snap.goal_m),
        "commanded_joints_rad": floats(snap.joints_commanded_rad),
        "measured_joints_rad": floats(snap.joints_measured_rad),
        "commanded_m": floats(snap.point_commanded_m),
        "measured_m": floats(snap.point_measured_m),
        "error_m": floats(snap.shown_error_m),
        # the servos' readings the tick already has (the plots' signals; no extra work)
        "current_a": floats(snap.readings["current_a"]),
        "pwm": floats(snap.readings["pwm"]),
        "ee": {
            "position_m": floats(snap.point_measured_m),
            "platform_m": floats(snap.platform_measured_m),
            "phi_rad": snap.tool_phi_rad,
            "goal_phi_rad": goal_phi(snap),
        },
        "loop": {
            "measured_hz": window.measured_hz,
            "jitter_p99_ms": window.jitter_p99_ms,
            "overruns": snap.loop_total.overruns,
        },
        "faults": [f.as_dict() for f in snap.faults],
        "world": world_frame(snap),
        "contact": contact(snap),  # the tip's force estimate (the plots' "tip force")
    }


def world_frame(snap: Snapshot) -> dict[str, Any] | None:
    """In hold-in-world with a known drone pose: goal, measured tool and error [m] in the
    world frame (error = goal - measured, as in the run stats); None otherwise."""
    extra = snap.extra or {}
    goal, measured = extra.get("goal_world_m"), extra.get("measured_world_m")
    if goal is None or measured is None:
        return None
    error = [g - m for g, m in zip(goal, measured, strict=True)]
    frame = {"goal_m": floats(goal), "measured_m": floats(measured), "error_m": floats(error)}
    frame["drone_pose"] = extra.get("drone_pose")  # position [m], quaternion (w, x, y, z)
    heading, seen = extra.get("heading_world_rad"), extra.get("measured_heading_world_rad")
    if heading is not None:  # a wrist keeps the tool's heading too
        frame["heading_rad"] = heading
        frame["heading_error_rad"] = None if seen is None else wrap(heading - seen)
        frame["heading_limited"] = bool(extra.get("heading_limited"))
    return frame

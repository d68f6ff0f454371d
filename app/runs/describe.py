"""A run in words and units: the test and its parameters, the loop's figures, the verdict.

The report figure, the API (``description``), the dashboard and the CLI say a run the same
way: lengths in mm, angles in degrees, times in s or ms, switches "on"/"off", never a Python
repr ("True", "(0.0, 0.0, -0.24)", "None"). Inputs are the run's saved ``params`` and
``conditions`` dicts (SI units, as in run.json) and its ``stats`` (``stats["health"]`` when
the loop's health was recorded; runs from before it have none).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

AXES = "xyz"
DASH = "–"  # a value that is missing or not a number


def number(value: Any, digits: int = 3) -> str:
    """A number for people: up to ``digits`` significant figures, no trailing zeros, a true
    minus sign; "–" for None, NaN or anything that is not a number."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return DASH
    text = f"{value:.{digits}g}"
    if "e" in text:  # very large or small: fixed notation reads better in a figure
        text = f"{value:.0f}" if abs(value) >= 1 else f"{value:.{digits}f}"
    return text.replace("-", "−") if value < 0 else text


def on_off(value: Any) -> str:
    return "on" if value else "off"


def _scaled(values: Any, scale: float, digits: int = 3) -> str:
    if isinstance(values, list | tuple):
        return " / ".join(number(v * scale if _real(v) else None, digits) for v in values)
    return number(values * scale if _real(values) else None, digits)


def _real(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def mm(value_m: Any) -> str:
    """Metres (one value or per axis) as mm: "50 / 50 / 80 mm"."""
    return f"{_scaled(value_m, 1e3)} mm"


def degrees(value_rad: Any) -> str:
    return f"{_scaled(value_rad, 180 / math.pi)}°"


def point(value_m: Any) -> str:
    """A point [m] as "(0, 0, −240) mm"."""
    if not isinstance(value_m, list | tuple):
        return mm(value_m)
    return "(" + ", ".join(number(v * 1e3) if _real(v) else DASH for v in value_m) + ") mm"


def _axis(index: Any) -> str:
    return AXES[index] if isinstance(index, int) and 0 <= index < 3 else DASH


def _feedforward(params: dict[str, Any], conditions: dict[str, Any]) -> str:
    if not params.get("feedforward"):
        return "feed-forward off"
    lead = conditions.get("feedforward_lead_s")
    return "feed-forward on" + (f", lead {number(lead * 1e3)} ms" if _real(lead) else "")


def _sinusoid(p: dict[str, Any]) -> str:
    return (
        f"sinusoid per axis x / y / z: amplitude {mm(p.get('amplitude_m'))}, "
        f"frequency {_scaled(p.get('frequency_hz'), 1.0)} Hz, "
        f"phase {degrees(p.get('phase_rad'))}, offset {mm(p.get('offset_m'))}; "
        f"{number(p.get('duration_s'))} s"
    )


def _chirp(p: dict[str, Any]) -> str:
    return (
        f"chirp on {_axis(p.get('axis'))}: amplitude {mm(p.get('amplitude_m'))}, "
        f"{number(p.get('f0_hz'))} → {number(p.get('f1_hz'))} Hz over "
        f"{number(p.get('duration_s'))} s about {point(p.get('offset_m'))}"
    )


def _step(p: dict[str, Any]) -> str:
    return (
        f"step on {_axis(p.get('axis'))}: {mm(p.get('size_m'))} at {number(p.get('step_at_s'))} s "
        f"of {number(p.get('duration_s'))} s, from {point(p.get('offset_m'))}"
    )


def _joint_step(p: dict[str, Any]) -> str:
    return (
        f"step of joint {number(p.get('joint'))} (servo {number(p.get('servo_id'))}): "
        f"{degrees(p.get('step_rad'))} at {number(p.get('step_at_s'))} s of "
        f"{number(p.get('duration_s'))} s, from joints {degrees(p.get('start_rad'))}"
    )


def _waypoints(p: dict[str, Any]) -> str:
    times = p.get("times_s") or []
    end = times[-1] if times else None
    return (
        f"waypoints: {len(p.get('points_m') or [])} points over {number(end)} s "
        "(minimum-jerk between, resting at each)"
    )


def _hold(p: dict[str, Any]) -> str:
    if p.get("source") == "external":  # on the pose input (the page's hold in world)
        goal = p.get("position_m")
        at = f"at {mm(goal)} in the world" if goal is not None else "where the tool was"
        return (
            f"hold in world on the pose input: {number(p.get('duration_s'))} s {at}, latency "
            f"compensation {on_off(p.get('latency_compensation'))}"
        )
    drone = p.get("drone") or p
    return (
        f"hold in world on the simulated drone: {number(p.get('duration_s'))} s, latency "
        f"compensation {on_off(p.get('latency_compensation'))}; drone drift "
        f"{mm(drone.get('drift_m'))}, tilt {number(drone.get('tilt_deg'))}°, yaw "
        f"{number(drone.get('yaw_deg'))}°, gusts {mm(drone.get('gust_m'))}, pose latency "
        f"{number(_ms(drone.get('latency_s')))} ms at {number(drone.get('rate_hz'))} Hz, "
        f"seed {number(drone.get('seed'), 12)}"
    )


def _program(p: dict[str, Any]) -> str:
    return (
        f"G-code program: {number(p.get('lines'), 12)} lines, {number(p.get('segments'), 12)} "
        f"segments, {number(p.get('duration_s'))} s, path {mm(p.get('length_m'))}, work "
        f"offset {_scaled(p.get('work_offset_m') or [], 1e3)} mm"
    )


def _ms(value_s: Any) -> Any:
    return value_s * 1e3 if _real(value_s) else None


_UNITS = (  # name suffix -> (scale, unit) for kinds without their own sentence
    ("_m", 1e3, " mm"),
    ("_rad", 180 / math.pi, "°"),
    ("_deg", 1.0, "°"),
    ("_s", 1.0, " s"),
    ("_hz", 1.0, " Hz"),
)


def _generic(kind: str, p: dict[str, Any]) -> str:
    parts = []
    for name, value in p.items():
        if name == "feedforward" or isinstance(value, dict):
            continue
        label, scale, unit = name, 1.0, ""
        for suffix, factor, symbol in _UNITS:
            if name.endswith(suffix):
                label, scale, unit = name[: -len(suffix)], factor, symbol
                break
        label = label.replace("_", " ")
        if isinstance(value, bool):
            parts.append(f"{label} {on_off(value)}")
        elif _real(value) or isinstance(value, list | tuple):
            parts.append(f"{label} {_scaled(value, scale)}{unit}")
        elif isinstance(value, str):
            parts.append(f"{label} {value}")
    return f"{kind}: " + ", ".join(parts) if parts else kind


SENTENCES: dict[str, Callable[[dict[str, Any]], str]] = {  # kind -> its sentence of params
    "sinusoid": _sinusoid,
    "chirp": _chirp,
    "step": _step,
    "joint-step": _joint_step,
    "waypoints": _waypoints,
    "hold": _hold,
    "program": _program,
}


def describe(kind: str, params: dict[str, Any], conditions: dict[str, Any] | None = None) -> str:
    """The test and its parameters in words and units, e.g. "sinusoid per axis x / y / z:
    amplitude 50 / 50 / 80 mm, frequency 1 / 1 / 2 Hz, phase 0 / 0 / 0°, offset
    0 / 0 / −240 mm; 10 s; feed-forward on, lead 20 ms". ``params`` and ``conditions`` as
    saved in run.json (SI units); a kind without its own sentence lists its parameters."""
    conditions = conditions or {}
    sentence = SENTENCES.get(kind)
    text = sentence(params) if sentence else _generic(kind, params)
    if kind == "hold" or "feedforward" not in params:
        return text
    return f"{text}; {_feedforward(params, conditions)}"


def loop_figures(stats: dict[str, Any], conditions: dict[str, Any] | None = None) -> str:
    """The control loop's figures from ``stats["health"]``: rate, lateness p50 / p99 /
    worst, overruns, the longest gap between ticks and stale feedback; "not recorded" for
    runs from before the loop's health was kept."""
    health = stats.get("health")
    target = (conditions or {}).get("loop_rate_hz")
    target_text = f" (target {number(target)} Hz)" if _real(target) else ""
    if not isinstance(health, dict):
        return f"loop{target_text}: figures not recorded for this run"
    lateness = health.get("lateness_ms") or {}
    share = health.get("overrun_share")
    share_text = f" ({number(share * 100, 2)} %)" if _real(share) else ""
    return (
        f"loop: {number(health.get('rate_hz'))} Hz{target_text}; lateness p50 "
        f"{number(lateness.get('p50'))} / p99 {number(lateness.get('p99'))} / worst "
        f"{number(lateness.get('worst'))} ms; overruns {number(health.get('overruns'), 12)}"
        f"{share_text}; longest gap {number(health.get('longest_gap_ms'))} ms; stale feedback "
        f"{number(health.get('stale_ticks'), 12)} ticks, longest "
        f"{number(health.get('longest_stale_ms'))} ms"
    )


def verdict(stats: dict[str, Any]) -> str:
    """Whether the run's figures can be trusted, from ``stats["health"]``: "healthy", or
    "NOT HEALTHY" with its reasons, or "not checked" for runs without a health record."""
    health = stats.get("health")
    if not isinstance(health, dict) or not isinstance(health.get("ok"), bool):
        return "verdict: not checked (run recorded before loop health was kept)"
    if health["ok"]:
        return "verdict: healthy loop and fresh feedback: the figures stand"
    reasons = "; ".join(str(r) for r in health.get("reasons") or []) or "no reason given"
    return f"verdict: NOT HEALTHY, the figures do not stand: {reasons}"


def outcome(state: str, reason: str | None) -> str:
    """How the run ended, e.g. "aborted (e-stop)"."""
    return f"{state} ({reason})" if reason else state

"""Machine-readable payloads and printed tables of ``deltadash design``."""

from __future__ import annotations

from typing import Any

import numpy as np
import tomli_w

from kinematics.containment import certify_box
from kinematics.sizing import Sizing
from kinematics.synthesis import THESIS_DESIGN, Design, Problem, SynthesisResult, check, score
from kinematics.synthesis import violations as find_violations

THESIS_SIZING = {"static_nm": 0.656, "peak_nm": 0.905, "speed_rpm": 48.0}
"""Thesis ch. 4.2, "Motor Selection and Sizing"."""


def _mm(values: Any) -> list[float]:
    return [round(float(v) * 1e3, 2) for v in values]


def design_check(problem: Problem, design: Design) -> dict[str, Any]:
    """How a design fares on a problem: objective, certification, violated constraints."""
    parts = score(problem, np.array(design))
    containment, extra_ok = check(problem, design)
    found = find_violations(problem, design)
    return {
        **{k: float(v) for k, v in design._asdict().items()},
        "objective": float(parts.objective),
        "power_of_point": float(parts.power_of_point),
        "violations": int(parts.violations),
        "contains": bool(containment.contains) and extra_ok,
        "extra_points_ok": extra_ok,
        # the thesis's own test (eq. 4.5): vertices and extra points, exact distances
        "vertices_missed": len({v.point for v in found}),
        "vertex_distance_mm": round(_vertex_distance(problem, design) * 1e3, 2),
        "witness_mm": None if containment.witness is None else _mm(containment.witness),
        "missed": [
            {
                "point_mm": _mm(v.point),
                "leg": v.leg + 1,
                "h_m4": v.h,
                "outside_mm": round(v.outside_m * 1e3, 2),
            }
            for v in found
        ],
    }


def _vertex_distance(problem: Problem, design: Design) -> float:
    """Largest signed distance [m] of the vertices and extra points (> 0: outside)."""
    return float(design.robot().signed_distance(problem.thesis_points(design.H)).max())


def thesis_readings() -> list[dict[str, Any]]:
    """Which box placements the thesis design (Table 4.3) really contains (certified)."""
    robot, H = THESIS_DESIGN.robot(), THESIS_DESIGN.H
    rows = []
    for edge in (0.22, 0.20):
        for reading, top in (("top face at -H", -H), ("centre at -H", -H + edge / 2)):
            lower = np.array([-edge / 2, -edge / 2, top - edge])
            upper = np.array([edge / 2, edge / 2, top])
            verdict = certify_box(robot, lower, upper)
            rows.append(
                {
                    "edge_m": edge,
                    "reading": reading,
                    "contains": bool(verdict.contains),
                    "worst_mm": round(verdict.worst_m * 1e3, 1),
                }
            )
    return rows


def synth_payload(
    result: SynthesisResult, problem: Problem, seconds: float, r: float
) -> dict[str, Any]:
    """JSON of ``design synth``: our design, its certification, and the thesis check."""
    ours = design_check(problem, result.design)
    return {
        **{k: float(v) for k, v in result.design._asdict().items()},
        "R": result.design.Rbar + r,
        "r": r,
        "objective": result.objective,
        "power_of_point": result.power_of_point,
        "contains": result.contains,
        "vertex_distance_mm": ours["vertex_distance_mm"],
        "vertices_missed": ours["vertices_missed"],
        "seconds": round(seconds, 2),
        "evaluations": result.evaluations,
        "rounds": result.rounds,
        "clearance_mm": problem.clearance_m * 1e3,
        "thesis": design_check(problem, THESIS_DESIGN),
        "thesis_readings": thesis_readings(),
    }


def design_toml(design: Design, r: float) -> str:
    """The ``[robot]`` section ``deltadash serve --config`` loads (app/config.py)."""
    robot = {"type": "rotary", "L": design.L, "l": design.l, "R": design.Rbar + r, "r": r}
    return tomli_w.dumps(
        {"robot": {k: (round(v, 6) if k != "type" else v) for k, v in robot.items()}}
    )


def synth_table(payload: dict[str, Any]) -> str:
    """Ours beside the thesis's Table 4.3, in mm."""
    thesis = payload["thesis"]
    lines = [f"{'':22}{'ours':>12}{'thesis 4.3':>12}"]
    for key in ("L", "l", "Rbar", "H"):
        lines.append(f"{key + ' [mm]':22}{payload[key] * 1e3:12.1f}{thesis[key] * 1e3:12.1f}")
    lines.append(
        f"{'power of point [m^4]':22}{payload['power_of_point']:12.5f}"
        f"{thesis['power_of_point']:12.5f}"
    )
    lines.append(
        f"{'vertices out of reach':22}{payload['vertices_missed']:>12}"
        f"{thesis['vertices_missed']:>12}"
    )
    lines.append(
        f"{'contains the volume':22}{str(payload['contains']):>12}{str(thesis['contains']):>12}"
    )
    lines.append(
        f"{'worst vertex [mm]':22}{payload['vertex_distance_mm']:12.1f}"
        f"{thesis['vertex_distance_mm']:12.1f}   (> 0: outside)"
    )
    lines.append(
        f"search: {payload['seconds']} s, {payload['evaluations']} designs, "
        f"{payload['rounds']} round(s)"
    )
    for reading in payload["thesis_readings"]:
        verdict = (
            "contains (certified)"
            if reading["contains"]
            else f"misses (a point {reading['worst_mm']} mm outside)"
        )
        lines.append(
            f"thesis design, {reading['edge_m'] * 100:.0f} cm box with "
            f"{reading['reading']}: {verdict}"
        )
    return "\n".join(lines)


def sizing_payload(sized: Sizing, level: Sizing, link_only: Sizing) -> dict[str, Any]:
    """JSON of ``design size``: worst cases, the servo check, and the thesis's figures."""

    def worst(w: Any) -> dict[str, Any]:
        return {"value": round(w.value, 4), "point_mm": _mm(w.point), "joint": w.joint + 1}

    return {
        "static_nm": worst(sized.static_nm),
        "peak_nm": worst(sized.peak_nm),
        "speed_rpm": worst(sized.speed_rpm),
        "level_drone": {
            "static_nm": round(level.static_nm.value, 4),
            "peak_nm": round(level.peak_nm.value, 4),
        },
        "peak_nm_link_inertia_only": round(link_only.peak_nm.value, 4),
        "servo": {
            "name": sized.servo.name,
            "stall_nm": sized.servo.stall_nm,
            "no_load_rpm": sized.servo.no_load_rpm,
        },
        "available_nm_at_speed": round(sized.available_nm, 4),
        "torque_margin": round(sized.torque_margin, 3),
        "speed_margin": round(sized.speed_margin, 3),
        "passes": sized.passes,
        "points": sized.points,
        "skipped": sized.skipped,
        "thesis": THESIS_SIZING,
    }


def peak_cause_text(payload: dict[str, Any]) -> str:
    """Why the peak torque is what it is, and why it differs from the thesis's 0.905 N m
    (docs/design.md, "Motor sizing"); ``payload["peak_cause"]`` from ``design size``."""
    c = payload["peak_cause"]
    peak = payload["peak_nm"]["value"]
    point = ", ".join(f"{v:g}" for v in c["point_mm"])
    angles = ", ".join(f"{v:g}" for v in c["joints_deg"])
    speed = f", {c['speed_rpm_there']:g} rpm there for the speed" if c["speed_rpm_there"] else ""
    servo = payload["servo"]
    if payload["passes"]:
        verdict = "The servo passes."
    elif payload["speed_margin"] < 1:
        verdict = (
            f"FAIL because the joint speed needed ({payload['speed_rpm']['value']:.0f} rpm) "
            f"is above the servo's {servo['no_load_rpm']:g} rpm no-load speed, so no torque "
            "is left at that speed (the speed constraint), not because of the static load."
        )
    else:
        verdict = (
            f"FAIL because the servo gives only {payload['available_nm_at_speed']:.3f} N m at "
            f"the top speed, below the peak (the torque constraint)."
        )
    below = "passes" if c["passes_below"] else "still fails"
    return "\n".join(
        [
            "",
            f"Why the peak torque is {peak:.3f} N m, not the thesis's "
            f"{THESIS_SIZING['peak_nm']} N m:",
            f"- It happens at ({point}) mm, joint {c['joint']}, near the top of the region: "
            f"{c['boundary_distance_mm']:g} mm from the workspace boundary, joint angles "
            f"({angles}) deg, a link pointing almost straight up{speed}.",
            f"- There the speed constraint (--speed in any direction) needs large joint speeds "
            f"and accelerations, and those times the servo's reflected rotor inertia give the "
            f"peak: at zero speed (gravity and --acceleration only) it is "
            f"{c['peak_nm_zero_speed']:.3f} N m, with "
            f"the link's inertia only (no rotor) {payload['peak_nm_link_inertia_only']:.3f} N m.",
            f"- Away from the top (z <= {c['below_z_mm']:g} mm) the peak is "
            f"{c['peak_nm_below']:.3f} N m at {c['speed_rpm_below']:g} rpm and the servo "
            f"{below}.",
            "- The thesis states no region, pose or mass model for its 0.905 N m; it lies "
            "within the spread above (the tool is not wrong, the figures answer different "
            'questions). See docs/design.md, "Motor sizing".',
            f"- {verdict}",
        ]
    )


def sizing_table(payload: dict[str, Any]) -> str:
    rows = [
        ("static torque [N m]", payload["static_nm"], THESIS_SIZING["static_nm"]),
        ("peak torque [N m]", payload["peak_nm"], THESIS_SIZING["peak_nm"]),
        ("joint speed [rpm]", payload["speed_rpm"], THESIS_SIZING["speed_rpm"]),
    ]
    lines = [f"{'':22}{'ours':>9}{'thesis':>9}   worst at (mm), joint"]
    for name, ours, thesis in rows:
        lines.append(
            f"{name:22}{ours['value']:9.3f}{thesis:9.3f}   "
            f"{tuple(ours['point_mm'])}, {ours['joint']}"
        )
    level = payload["level_drone"]
    lines.append(
        f"level drone: static {level['static_nm']:.3f} N m, peak {level['peak_nm']:.3f}"
        f" N m; peak with the link's inertia only (no rotor): "
        f"{payload['peak_nm_link_inertia_only']:.3f} N m"
    )
    servo = payload["servo"]
    verdict = "PASS" if payload["passes"] else "FAIL"
    lines.append(
        f"{servo['name']}: {servo['stall_nm']} N m stall, {servo['no_load_rpm']} rpm "
        f"no load -> {payload['available_nm_at_speed']:.3f} N m at the top speed; "
        f"torque margin x{payload['torque_margin']}, speed margin "
        f"x{payload['speed_margin']}: {verdict}"
    )
    lines.append(
        f"grid points used {payload['points']}, skipped (out of reach or singular) "
        f"{payload['skipped']}"
    )
    return "\n".join(lines)

"""The files a ``deltadash design synth --out`` run writes: the design as config, its report
(JSON and Markdown) and, for our design and the thesis's, the box over a workspace section."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from app.design import report
from kinematics.analysis import section
from kinematics.synthesis import Problem, SynthesisResult


def write_synthesis_report(
    out: Path,
    result: SynthesisResult,
    problem: Problem,
    payload: dict[str, Any],
    platform_radius_m: float,
) -> list[Path]:
    """Write design.toml, report.json, report.md and one PNG per design into ``out``.

    Returns the paths written, in that order.
    """
    from app.design import figures  # matplotlib only when files are asked for

    out.mkdir(parents=True, exist_ok=True)
    toml_path = out / "design.toml"
    toml_path.write_text(report.design_toml(result.design, platform_radius_m))
    json_path = out / "report.json"
    json_path.write_text(json.dumps(payload, indent=2))
    text_path = out / "report.md"
    text_path.write_text(
        f"# Synthesis report\n\n```\n{report.synth_table(payload)}\n```\n\n"
        "See docs/design.md for the problem and the certification.\n"
    )
    paths = [toml_path, json_path, text_path]
    for name, design in (("ours", result.design), ("thesis", report.THESIS_DESIGN)):
        lower, upper = problem.volume.box(design.H)
        robot = design.robot(platform_radius_m)
        extent = (-0.35, 0.35, -0.5, 0.0)
        cut = section(robot, "xz", float(upper[1]), extent=extent)  # the box's far face
        witness = payload["thesis"]["witness_mm"] if name == "thesis" else None
        witness = None if witness is None else np.array(witness) / 1e3
        title = (
            f"{name}: L {design.L * 1e3:.1f}, l {design.l * 1e3:.1f}, Rbar "
            f"{design.Rbar * 1e3:.1f}, H {design.H * 1e3:.1f} mm; section y = "
            f"{upper[1] * 1e3:.0f} mm"
        )
        paths.append(
            figures.box_over_section(cut, lower, upper, out / f"synth_{name}.png", title, witness)
        )
    return paths

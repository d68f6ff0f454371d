"""The check's findings read right (issue 32 item 5): a limit violation says the value
reached, the limit and by how much; each move's first cause first, the others folded
under it (``folded_under``), so examples/fails.ngc gives one first cause on each of its
two bad lines."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from app.config import load_settings
from app.control.commands import CommandContext
from app.programs.check import check_program
from app.programs.verify import Violation, fold

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
START = (0.0, 0.0, -0.24)


@pytest.fixture(scope="module")
def settings():
    return load_settings()


@pytest.fixture(scope="module")
def gate(settings):
    return CommandContext.from_settings(settings).gate


def test_a_joint_limit_says_the_angle_reached_the_limit_and_by_how_much(settings, gate):
    """Up from (30, 0, -240) to (30, 0, -100) mm at 10 mm/s, inside the workspace: joint 1
    (link up) passes its lower limit; the worst sample is the end, where the path rests,
    so the angle is the IK's at (30, 0, -100) mm: -41.59 deg, 7.21 deg past -34.38 deg."""
    text = "G21 G90\nG1 F600 X30 Y0 Z-240\nZ-100\nM2"
    report = check_program(text, settings, start_m=START).report
    [violation] = report.violations  # nothing else is wrong with the move
    assert (violation.line, violation.kind, violation.folded_under) == (3, "joint_limit", None)
    ik = gate.robot.ik(np.array([0.03, 0.0, -0.1]))
    reached = math.degrees(float(ik.joints[0]))
    low = math.degrees(float(gate.joint_min_rad[0]))
    assert reached == pytest.approx(-41.59, abs=0.01) and low == pytest.approx(-34.38, abs=0.01)
    assert violation.message == (
        f"joint 1 reaches {reached:.1f} deg, {low - reached:.1f} deg beyond its lower "
        f"limit {low:.1f} deg"
    )
    assert violation.message == (
        "joint 1 reaches -41.6 deg, 7.2 deg beyond its lower limit -34.4 deg"
    )


def test_the_ceiling_says_the_height_reached_and_by_how_much(settings):
    """Up to z = -40 mm through the ceiling at -60 mm: 20 mm above it at the top."""
    report = check_program("G90 G1 F1200 Z-220\nZ-40\nZ-220", settings, start_m=START).report
    ceiling = [v for v in report.violations if v.kind == "ceiling"]
    assert [v.line for v in ceiling] == [2, 3]
    for v in ceiling:
        assert v.message == (
            "the platform reaches z = -40.00 mm, 20.00 mm above the ceiling z = -60.0 mm"
        )


def test_the_workspace_says_how_far_outside(settings, gate):
    """At the top of examples/fails.ngc's climb, (30, 0, -55) mm: the distance outside is
    at most the height above the workspace's edge on that vertical (found by the IK alone,
    bisected), and not much less (the edge is nearly flat there)."""
    report = check_program((EXAMPLES / "fails.ngc").read_text(), settings).report
    [line6] = [v for v in report.violations if v.kind == "workspace" and v.line == 6]
    outside_mm, past_mm = (float(word) for word in line6.message.split()[0:6:5])
    assert line6.message == (
        f"{outside_mm:.1f} mm outside the workspace, {past_mm:.1f} mm past the 2.0 mm kept "
        "inside its edge"
    )
    assert past_mm == pytest.approx(outside_mm + gate.margin_m * 1e3, abs=0.051)
    inside, outside = -0.240, -0.055  # z [m] on x = 30 mm: reached, not reached
    for _ in range(50):
        middle = 0.5 * (inside + outside)
        if gate.robot.ik(np.array([0.03, 0.0, middle])).ok:
            inside = middle
        else:
            outside = middle
    above_mm = (-0.055 - inside) * 1e3  # 30.6 mm above the edge on that vertical
    assert above_mm - 3.0 < outside_mm <= above_mm + 0.05


def test_a_point_within_the_margin_says_how_far_into_it(settings, gate):
    """Up to (30, 0, -86.5) mm: in reach (joint 1 past its limit first), but 0.84 mm from
    the workspace's edge (the legs' signed distance), 1.16 mm into the 2 mm margin; the
    edge on that vertical (the IK's) is above it by less than the margin."""
    text = "G21 G90\nG1 F600 X30 Y0 Z-240\nZ-86.5\nM2"
    report = check_program(text, settings, start_m=START).report
    assert [(v.line, v.kind, v.folded_under) for v in report.violations] == [
        (3, "joint_limit", None),
        (3, "workspace", 0),
    ]
    assert gate.robot.ik(np.array([0.03, 0.0, -0.0865])).ok
    assert not gate.robot.ik(np.array([0.03, 0.0, -0.0865 + gate.margin_m])).ok
    assert report.violations[1].message == (
        "0.8 mm inside the workspace's edge, 1.2 mm into the 2.0 mm kept inside its edge"
    )


def test_the_failing_example_gives_one_first_cause_per_bad_line(settings):
    """examples/fails.ngc: 12 violations on lines 5 and 6, read as two first causes.
    Line 5 climbs: joint 1 passes its lower limit (link up) at z = -107 mm, before the
    workspace's edge, the loss of the IK and the ceiling; its acceleration and torque
    peaks are what the joints do at the edge. Line 6 starts up there: outside the
    workspace, above the ceiling and without IK at its first sample (workspace first by
    the order of causes), its joint limit on the way back down."""
    report = check_program((EXAMPLES / "fails.ngc").read_text(), settings).report
    violations = report.violations
    assert len(violations) == 12
    firsts = [(k, v) for k, v in enumerate(violations) if v.folded_under is None]
    assert [(v.line, v.kind) for _, v in firsts] == [(5, "joint_limit"), (6, "workspace")]
    assert firsts[0][1].message == (
        "joint 1 reaches -76.6 deg, 42.2 deg beyond its lower limit -34.4 deg"
    )
    for k, first in firsts:  # each move's first cause leads it, the others folded under it
        folded = [v for v in violations if v.folded_under == k]
        assert len(folded) == 5 and {v.line for v in folded} == {first.line}
        assert violations[k + 1 : k + 6] == folded
        assert [v.t_s for v in folded] == sorted(v.t_s for v in folded)
        assert all(first.t_s <= v.t_s for v in folded)
    kinds = {"workspace", "ceiling", "ik", "joint_limit", "joint_acceleration", "torque"}
    for line in (5, 6):
        assert {v.kind for v in violations if v.line == line} == kinds


def violation(line: int, kind: str, t_s: float) -> Violation:
    return Violation(line, kind, kind, t_s, (0.0, 0.0, -0.2))


def test_the_first_cause_is_where_the_point_is_before_what_the_joints_do():
    """A rate or torque finding one sample before a position one on the same line folds
    under it; a line of rates only starts with its earliest (ties: speed, acceleration,
    torque); a run_duration is a first cause of its own."""
    found = [
        violation(2, "torque", 1.00),
        violation(2, "joint_acceleration", 1.00),
        violation(2, "workspace", 1.01),
        violation(2, "ik", 1.01),
        violation(3, "torque", 2.0),
        violation(3, "joint_acceleration", 2.0),
        violation(3, "run_duration", 2.5),
        violation(3, "joint_speed", 2.6),
    ]
    folded = fold(found)
    assert [(v.line, v.kind, v.folded_under) for v in folded] == [
        (2, "workspace", None),
        (2, "joint_acceleration", 0),
        (2, "torque", 0),
        (2, "ik", 0),
        (3, "joint_acceleration", None),
        (3, "torque", 4),
        (3, "joint_speed", 4),
        (3, "run_duration", None),
    ]
    assert all(v.folded_under is None for v in found)  # the input is left as it was
    assert fold(folded) == folded  # folding a folded list changes nothing

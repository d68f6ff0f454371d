"""Field reports on G-code (issue 28 section 3): percent lines, tiny CAM arcs, huge-radius
arcs and the order faults are reported in."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.config import load_settings
from app.programs.check import check_program
from app.programs.errors import ProgramError
from app.programs.modal import interpret
from app.programs.planner import plan_program
from app.programs.tokens import iter_lines

START = (0.0, 0.0, -0.24)
ZERO = (0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def settings():
    return load_settings()


def run(text, start=START, offset=ZERO):
    return interpret(iter_lines(text), start, offset)


# --- 1. percent lines (RS274/NGC) ---------------------------------------------------------


def test_nothing_after_the_closing_percent_line_is_run_or_read():
    """RS274/NGC: the useful contents of a % ... % file stop at the second % line."""
    text = "%\nG0 X0 Y0 Z-240\nG1 X10 F600\n%\nG0 X30 Y0 Z-100"
    program = run(text)
    assert [s.kind for s in program.segments] == ["linear"]  # no rapid to z = -100 mm
    np.testing.assert_allclose(program.segments[-1].end_m, (0.01, 0.0, -0.24), atol=1e-15)
    assert program.lines == 4  # the program ends at its closing % line
    # what follows the closing % is not even read: not G-code there is no fault
    assert run("(title)\n%\nG1 X1 F10\n%\nthis is a note, #1 = 2 (\n").lines == 4


def test_a_file_opened_by_percent_and_never_closed_is_refused_at_its_end():
    text = "\n%\nG1 X1 F10\nG1 X2\n"  # lines 1-5 (the last one empty)
    with pytest.raises(ProgramError) as caught:
        run(text)
    assert caught.value.line == 5 and caught.value.word == ""
    assert "line 2" in caught.value.reason and "%" in caught.value.reason
    # ended by M2 (the reading stops there, as LinuxCNC's does): no closing % needed
    assert [s.kind for s in run("%\nG1 X1 F10\nM2\nG1 X2").segments] == ["linear"]
    # a % line in a file that does not open with one is only a delimiter, as before
    assert len(run("G1 X1 F10\n%\nG1 X2").segments) == 2


def test_the_check_refuses_an_unclosed_percent_file_naming_the_line(settings):
    with pytest.raises(ProgramError, match=r"^line 3: .*line 1"):
        check_program("%\nG1 F600 X1 Y0 Z-240\nG1 X2", settings)


# --- 2. a tiny CAM arc is not a full circle ----------------------------------------------

GRBL_496 = "G0 X51.311499 Y34.515665 Z0\nG1 F1500\nG02 X51.315904 Y34.520094 I0.782299 J-0.773466"
GRBL_496_OFFSET = (-0.05, -0.034, -0.24)  # the work offset of grbl#496's program [m]


def test_a_6_um_chord_arc_sweeps_what_it_says(settings):
    """grbl#496: from X51.311499 Y34.515665 the arc to X51.315904 Y34.520094 about the
    centre (52.093798, 33.742199) has a chord of 6.2466 um on a radius of 1.10011 mm: it
    turns 2 asin(c / 2r) = 0.32534 deg clockwise over 6.2466 um (by hand), never -360 deg
    over 6.9 mm."""
    program = run(GRBL_496, offset=GRBL_496_OFFSET)
    arc = program.segments[-1]
    assert arc.kind == "arc"
    assert math.degrees(arc.sweep_rad) == pytest.approx(-0.32534, abs=1e-5)
    assert arc.curve().length == pytest.approx(6.2466e-6, rel=1e-4)
    start = (0.001311499, 0.000515665, -0.24)  # where the G0 puts the tool (base frame)
    checked = check_program(GRBL_496, settings, start_m=start, work_offset_m=GRBL_496_OFFSET)
    assert checked.report.ok
    assert checked.report.length_m == pytest.approx(6.2466e-6, rel=1e-4)
    np.testing.assert_allclose(checked.report.path_m[-1], (0.001315904, 0.000520094, -0.24))


def test_an_arc_whose_end_is_its_start_is_still_a_full_circle():
    """grbl#495: from X30 Y30, G03 X30 Y30 I-4.24264 J-4.24264 is one turn of radius
    4.24264 sqrt(2) = 5.99999 mm: 37.6991 mm of path."""
    program = run("G0 X30 Y30 Z-240\nG1 F600\nG03 X30 Y30 I-4.24264 J-4.24264")
    arc = program.segments[-1]
    assert arc.sweep_rad == pytest.approx(2 * math.pi)
    assert arc.curve().length == pytest.approx(2 * math.pi * 4.24264 * math.sqrt(2) * 1e-3)


def test_a_short_r_arc_is_not_taken_for_a_full_circle():
    """An R arc of a 5 um chord was refused as 'a full circle'; with R1 (mm) it turns
    2 asin(0.0025) = 0.28648 deg counter-clockwise."""
    arc = run("G1 F600 X0 Y0 Z-240\nG3 X0.005 Y0 R1").segments[-1]
    assert math.degrees(arc.sweep_rad) == pytest.approx(0.28648, abs=1e-5)
    with pytest.raises(ProgramError, match="full circle"):
        run("G1 F600 X0 Y0 Z-240\nG3 X0 Y0 R1")


# --- 3. huge-radius arcs -------------------------------------------------------------------

UGS_2517 = "G0 X-27.306 Y72.929 Z-4\nG2 X-27.306 Y52.107 Z-4 I-2426220.106 J-10.411 F700"
UGS_OFFSET = (0.0, -0.06, -0.236)  # puts the pocket inside the workspace [m]


def test_a_freecad_arc_of_2426_m_radius_is_planned_as_the_near_line_it_is(settings):
    """UGS#2517: the centre is 2,426,220.106 mm to the left, 10.411 mm below the start;
    the end is its mirror image above the centre line: the arc turns
    -2 atan(10.411 / 2426220.106) = -8.5821e-6 rad along 20.822 mm, its middle
    c^2 / 8R = 2.2336e-5 mm off the chord (by hand)."""
    program = run(UGS_2517, offset=UGS_OFFSET)
    arc = program.segments[-1]
    assert arc.kind == "arc"
    assert arc.sweep_rad == pytest.approx(-8.5821e-6, rel=1e-4)
    assert arc.curve().length == pytest.approx(20.822e-3, rel=1e-9)
    path = plan_program([arc], _limits(settings))  # the arc alone, from rest to rest
    end = path.evaluate(np.array([path.duration_s]), (0,))[0][0]
    np.testing.assert_allclose(end, arc.end_m, atol=1e-12)  # no precision lost
    middle = path.evaluate(np.array([path.duration_s / 2]), (0,))[0][0]
    # the middle bulges 2.2337e-5 mm from the chord, away from the centre (+x)
    assert middle[0] - arc.start_m[0] == pytest.approx(2.2337e-8, rel=1e-3)
    start = (-0.027306, 0.012929, -0.24)
    checked = check_program(UGS_2517, settings, start_m=start, work_offset_m=UGS_OFFSET)
    assert checked.report.ok, checked.report.violations


def _limits(settings):
    from app.programs.check import plan_limits

    return plan_limits(settings)


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        # the huge arc's end moved 0.1 mm radially: 0.1 mm off its circle, refused although
        # 0.1 % of its radius is 2.4 m
        (
            "G0 X-27.306 Y72.929 Z-4\nG2 X-27.206 Y52.107 Z-4 I-2426220.106 J-10.411 F700",
            "further from the centre",
        ),
        # 0.05 mm off a 100 mm radius (0.05 %): over LinuxCNC's 0.0283 mm
        ("G0 X100 Y0 Z-4\nG3 X0 Y100.05 I-100 J0 F700", "further from the centre"),
    ],
)
def test_an_end_off_its_circle_is_refused_whatever_the_radius(text, reason):
    with pytest.raises(ProgramError, match=reason) as caught:
        run(text, offset=UGS_OFFSET)
    assert caught.value.line == 2 and caught.value.word in ("G2", "G3")


@pytest.mark.parametrize(
    ("arc", "word"),
    [
        ("G2 X0 Y-10 I-2000000000 J-5", "G2"),  # 2,000 km
        ("G2 X0 Y-10 R" + "1" * 160, "R" + "1" * 160),  # 1e159 mm: would overflow R^2
    ],
)
def test_a_radius_beyond_the_arithmetic_is_refused_saying_what_to_write(arc, word):
    with pytest.raises(ProgramError) as caught:
        run(f"G0 X0 Y0 Z-240\n{arc} F700")
    assert (caught.value.line, caught.value.word) == (2, word)
    assert "over 1,000 km" in caught.value.reason and "G1" in caught.value.reason


# --- the first fault of a file first -------------------------------------------------------


def test_the_first_fault_by_line_is_reported_before_a_later_unreadable_line(settings):
    """A semantic fault on line 2 (G92), unreadable text on line 5 (#1): line 2."""
    text = "G21\nG92 X0\nG1 F600 X1 Y0 Z-240\nG1 X2\n#1 = 2\n"
    with pytest.raises(ProgramError) as caught:
        check_program(text, settings)
    assert (caught.value.line, caught.value.word) == (2, "G92")
    # without the early fault the late one is found
    with pytest.raises(ProgramError) as caught:
        check_program(text.replace("G92 X0", ""), settings)
    assert caught.value.line == 5

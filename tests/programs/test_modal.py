"""The modal machine's laws: distance modes, units, planes, arc centre modes, refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.programs.errors import ProgramError
from app.programs.modal import interpret, work_offset_from_tool
from app.programs.tokens import tokenize

START = (0.0, 0.0, -0.24)
ZERO = (0.0, 0.0, 0.0)


def run(text, start=START, offset=ZERO):
    return interpret(tokenize(text), start, offset)


def ends(program):
    return np.array([s.end_m for s in program.segments]).reshape(-1, 3)


steps_mm = st.lists(
    st.tuples(*[st.integers(-50_000, 50_000).map(lambda v: v / 1000)] * 3), min_size=1, max_size=8
)


@settings(max_examples=50, deadline=None)
@given(steps_mm)
def test_incremental_and_absolute_programs_reach_the_same_points(steps):
    """G91 steps and G90 running sums are the same path (and back to G90 is absolute)."""
    relative = "G91 F100\n" + "\n".join(f"G1 X{x} Y{y} Z{z}" for x, y, z in steps)
    totals = np.cumsum(np.array(steps), axis=0) + np.array(START) * 1e3
    absolute = "G90 F100\n" + "\n".join(f"G1 X{x:.9f} Y{y:.9f} Z{z:.9f}" for x, y, z in totals)
    a, b = run(relative), run(absolute)
    moved = [i for i, s in enumerate(np.array(steps)) if np.any(s != 0)]
    assert len(a.segments) == len(moved)
    np.testing.assert_allclose(ends(a), ends(b), atol=1e-11)
    np.testing.assert_allclose(ends(a), totals[moved] * 1e-3, atol=1e-11)


def test_missing_axes_keep_their_value_in_both_modes():
    program = run("G90 G1 F100 X10\nY5\nG91 Z1")
    np.testing.assert_allclose(ends(program)[-1], [0.010, 0.005, -0.239])


@settings(max_examples=30, deadline=None)
@given(st.tuples(*[st.integers(-2000, 2000).map(lambda v: v / 100)] * 3), st.integers(1, 500))
def test_inches_are_25_4_mm_feeds_included(point, feed):
    x, y, z = point
    inch = run(f"G20 G90 G1 F{feed} X{x} Y{y} Z{z}", start=ZERO)
    mm = run(
        f"G21 G90 G1 F{feed * 25.4:.9f} X{x * 25.4:.9f} Y{y * 25.4:.9f} Z{z * 25.4:.9f}", start=ZERO
    )
    if not inch.segments:
        assert not mm.segments
        return
    np.testing.assert_allclose(inch.segments[0].end_m, mm.segments[0].end_m, atol=1e-12)
    assert inch.segments[0].feed_m_s == pytest.approx(feed * 0.0254 / 60)
    assert mm.segments[0].feed_m_s == pytest.approx(feed * 0.0254 / 60)


def test_feed_is_read_in_the_units_of_the_move():
    # F as written, G20 on the same line or after: inches per minute either way
    for text in ("F10 G20 G1 X1", "G20 F10 G1 X1", "F10\nG20\nG1 X1"):
        assert run(text, start=ZERO).segments[0].feed_m_s == pytest.approx(10 * 0.0254 / 60)


def test_quarter_arcs_in_each_plane_turn_about_its_normal():
    """G17/G18/G19: (e1, e2, n) = (x, y, z), (z, x, y), (y, z, x); G3 turns +90 deg about n
    from e1 to e2, and I/J/K are the x/y/z offsets to the centre."""
    cases = {
        "G17": ("X0 Y10 I-10 J0", (10, 0, 0), (0, 10, 0)),
        "G18": ("X10 Z0 I0 K-10", (0, 0, 10), (10, 0, 0)),
        "G19": ("Y0 Z10 J-10 K0", (0, 10, 0), (0, 0, 10)),
    }
    for plane, (words, start_mm, end_mm) in cases.items():
        start = tuple(v * 1e-3 for v in start_mm)
        segment = run(f"{plane} G3 F100 {words}", start=start).segments[0]
        assert segment.plane == plane and segment.direction == "ccw"
        np.testing.assert_allclose(segment.centre_m, ZERO, atol=1e-15)
        np.testing.assert_allclose(segment.end_m, np.array(end_mm) * 1e-3, atol=1e-15)
        assert segment.sweep_rad == pytest.approx(math.pi / 2)
        clockwise = run(f"{plane} G2 F100 {words}", start=start).segments[0]
        assert clockwise.sweep_rad == pytest.approx(-3 * math.pi / 2)


def test_an_offset_outside_the_plane_is_refused():
    with pytest.raises(ProgramError, match="K is not an arc offset in the G17 plane") as caught:
        run("G1 F100 X1\nG17 G2 X2 Y1 K1 I1", start=ZERO)
    assert (caught.value.line, caught.value.word) == (2, "K1")


@pytest.mark.parametrize("direction", ["G2", "G3"])
def test_arc_centre_modes_and_radius_form_agree(direction):
    start = (0.01, 0.0, -0.24)
    relative = run(f"G91.1 F100 {direction} X0 Y10 Z-240 I-10 J0", start=start)
    absolute = run(f"G90.1 F100 {direction} X0 Y10 Z-240 I0 J0", start=start)
    for program in (relative, absolute):
        np.testing.assert_allclose(program.segments[0].centre_m, ZERO[:2] + (-0.24,), atol=1e-15)
    # R > 0: the short way (G3 here: 90 deg), R < 0 the long way (G2 here: 270 deg)
    r = "R10" if direction == "G3" else "R-10"
    radius = run(f"F100 {direction} X0 Y10 Z-240 {r}", start=start).segments[0]
    np.testing.assert_allclose(radius.centre_m, (0.0, 0.0, -0.24), atol=1e-15)
    assert radius.sweep_rad == pytest.approx(relative.segments[0].sweep_rad)


def test_absolute_arc_centres_are_in_the_work_frame():
    offset = (0.001, 0.002, 0.0)
    start = (0.011, 0.002, -0.24)
    segment = run("G90.1 G3 F100 X0 Y10 I0 J0", start=start, offset=offset).segments[0]
    np.testing.assert_allclose(segment.centre_m, (0.001, 0.002, -0.24), atol=1e-15)


def test_a_full_circle_and_a_helix():
    program = run("G91 F100 G2 I-10 Z-5", start=(0.01, 0.0, -0.24))
    segment = program.segments[0]
    assert segment.sweep_rad == pytest.approx(-2 * math.pi)
    np.testing.assert_allclose(segment.end_m, (0.01, 0.0, -0.245))


def test_an_end_off_the_circle_is_refused():
    with pytest.raises(ProgramError, match="further from the centre"):
        run("G3 F100 X0 Y11 I-10 J0", start=(0.01, 0.0, -0.24))


def test_work_offset_from_the_tool_round_trips():
    tool = (0.012, -0.003, -0.21)
    offset = work_offset_from_tool(tool, (5.0, 7.0, 30.0))
    program = run("G90 G1 F100 X5 Y7 Z30\nG1 X6", start=(0.0, 0.0, -0.2), offset=offset)
    np.testing.assert_allclose(program.segments[0].end_m, tool, atol=1e-15)
    np.testing.assert_allclose(program.segments[1].end_m, (0.013, -0.003, -0.21), atol=1e-15)


def test_dwell_pause_and_end():
    program = run("G4 P0.25\nM0\nG1 F10 X1\nM2\nG1 X2")
    kinds = [s.kind for s in program.segments]
    assert kinds == ["dwell", "pause", "linear"]  # nothing after M2 runs
    assert program.segments[0].dwell_s == 0.25


@pytest.mark.parametrize(
    ("text", "line", "word", "reason"),
    [
        ("G1 F10 X1\nG1 A10", 2, "A10", "wrist axis is not configured"),
        ("G1 F10 X1\nG92 X0", 2, "G92", "not supported"),
        ("G1 F10 X1\nM3", 2, "M3", "not supported"),
        ("G1 F10 X1\nS1000", 2, "S1000", "not a word of the subset"),
        ("G1 F10 X1\nT1", 2, "T1", "not a word of the subset"),
        ("G21\nG1 X1", 2, "G1", "give F first"),
        ("G21\nX1", 2, "X1", "without a motion mode"),
        ("G1 F10 X1\nG0 G1 X1", 2, "G1", "modal group"),
        ("G1 F10 X1\nG4", 2, "G4", "needs P"),
        ("G1 F10 X1\nG1 X2 P1", 2, "P1", r"G4 \(dwell\) or G64"),
        ("G1 F10 X1\nG1 X2 I1", 2, "I1", "need G2 or G3"),
        ("G1 F10 X1\nG2 X2", 2, "G2", "needs R or its centre"),
        ("G1 F10 X1\nG2 X1 R5", 2, "R5", "full circle"),
        ("G1 F10 X1\nG2 X30 R5", 2, "R5", "under half the chord"),
        ("G1 F10 X1\nG1 F0 X2", 2, "F0", "> 0"),
        ("G1 F10 X1\nM2\nG1 Q1", 3, "Q1", "not a word"),  # read after M2, not run
    ],
)
def test_words_outside_the_subset_are_refused_with_line_and_word(text, line, word, reason):
    with pytest.raises(ProgramError, match=reason) as caught:
        run(text, start=ZERO)
    assert (caught.value.line, caught.value.word) == (line, word)


def test_g64_sets_the_blend_tolerance_and_g61_clears_it():
    program = run("G64 P0.1\nG1 F100 X1\nG64\nG1 X2\nG61\nG1 X3")
    assert [s.blend_m for s in program.segments] == [pytest.approx(1e-4), math.inf, None]
    assert run("G20 G64 P0.1 G1 F1 X1").segments[0].blend_m == pytest.approx(0.1 * 0.0254)

"""The planned path: arcs on their circles within the chord tolerance, dwells, lines,
derivatives, and the hand-off to the run manager's planner."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.programs.modal import interpret
from app.programs.planner import PlanLimits, plan_program
from app.programs.tokens import tokenize
from app.runs.trajectories import plan_sinusoid

LIMITS = PlanLimits(0.5, 4.0, 100.0, 2.0, 50.0, 1e-5, 0.005)
START = (0.0, 0.0, -0.24)


def plan(text, start=START, limits=LIMITS):
    return plan_program(interpret(tokenize(text), start, (0.0, 0.0, 0.0)).segments, limits)


def test_a_quarter_arc_stays_on_its_circle_and_ends_exactly():
    """G3 from (10, 0) to (0, 10) about (0, 0) at z = -240 mm: every sample at radius
    10 mm, the angle rising from 0 to 90 deg, z constant."""
    path = plan("G90 G3 F600 X0 Y10 Z-240 I-10 J0", start=(0.01, 0.0, -0.24))
    t = path.sample_times(0.001)
    p = path.derivatives(t, 0)
    np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), 0.01, rtol=1e-12)
    np.testing.assert_allclose(p[:, 2], -0.24)
    angle = np.arctan2(p[:, 1], p[:, 0])
    assert angle[0] == pytest.approx(0.0, abs=1e-12) and angle[-1] == pytest.approx(math.pi / 2)
    assert (np.diff(angle) >= -1e-12).all()
    assert path.length_m == pytest.approx(0.01 * math.pi / 2)


def test_a_helix_descends_in_proportion_to_its_turn():
    path = plan("G91 G2 F600 I-10 Z-4", start=(0.01, 0.0, -0.24))  # one turn, 4 mm down
    p = path.derivatives(path.sample_times(0.002), 0)
    turned = np.unwrap(np.arctan2(p[:, 1], p[:, 0]))  # clockwise: falling angle
    np.testing.assert_allclose(p[:, 2], -0.24 + 0.004 * turned / (2 * math.pi), atol=1e-12)
    assert turned[-1] == pytest.approx(-2 * math.pi)
    assert path.length_m == pytest.approx(math.hypot(2 * math.pi * 0.01, 0.004))


@pytest.mark.parametrize("radius_mm", [2.0, 10.0, 40.0])
def test_the_loops_chords_stay_within_the_tolerance(radius_mm):
    """Between two samples one period apart the loop moves on a chord; its middle is at
    most chord_tolerance_m inside the arc, however high the feed."""
    r = radius_mm * 1e-3
    limits = replace(LIMITS, chord_tolerance_m=1e-7, feed_jerk=5000.0)  # the chord limits
    path = plan(f"G3 F60000 I-{radius_mm}", start=(r, 0.0, -0.24), limits=limits)
    p = path.derivatives(path.sample_times(LIMITS.period_s), 0)
    middles = 0.5 * (p[1:] + p[:-1])
    sagitta = r - np.hypot(middles[:, 0], middles[:, 1])
    assert sagitta.max() <= limits.chord_tolerance_m * (1 + 1e-6)
    assert sagitta.max() >= 0.9 * limits.chord_tolerance_m


def test_arcs_keep_the_path_acceleration():
    path = plan("G3 F60000 I-20", start=(0.02, 0.0, -0.24))
    t = path.sample_times(0.001)
    a = path.derivatives(t, 2)
    assert np.linalg.norm(a, axis=1).max() <= LIMITS.feed_accel * (1 + 1e-9)


def test_a_dwell_lasts_its_p_seconds_and_holds_the_point():
    base = "G1 F600 X5\nG1 X10"
    with_dwell = "G1 F600 X5\nG4 P0.75\nG1 X10"
    a, b = plan(base), plan(with_dwell)
    assert b.duration_s - a.duration_s == pytest.approx(0.75, abs=1e-12)
    held = b.start_s[1] + np.linspace(0, 0.75, 7)
    np.testing.assert_allclose(b.derivatives(held, 0), [[0.005, 0.0, -0.24]] * 7, atol=1e-15)
    np.testing.assert_allclose(b.derivatives(held, 1), 0.0, atol=1e-15)
    assert set(b.line_at(held[1:-1]).tolist()) == {2}


def test_exact_stop_at_every_corner_and_lines_in_order():
    path = plan("G1 F3000 X20\nY20\nX0\nY0")
    corners = path.start_s[1:]
    np.testing.assert_allclose(path.derivatives(corners, 1), 0.0, atol=1e-12)
    t = path.sample_times(0.005)
    lines = path.line_at(t)
    assert lines[0] == 1 and lines[-1] == 4 and (np.diff(lines) >= 0).all()


def test_velocity_and_acceleration_are_the_derivatives_of_the_point():
    path = plan("G1 F3000 X20\nG2 X30 Y10 I0 J10\nG0 Z-200")
    dt = 1e-5
    t = np.linspace(0.001, path.duration_s - 0.001, 3001)
    for order in (1, 2):
        central = (path.derivatives(t + dt, order - 1) - path.derivatives(t - dt, order - 1)) / (
            2 * dt
        )
        scale = np.abs(path.derivatives(t, order)).max()
        np.testing.assert_allclose(central, path.derivatives(t, order), atol=2e-3 * scale)


def test_rapids_use_the_jog_limits_and_feeds_their_f():
    rapid, feed = plan("G0 X100"), plan("G1 F1200 X100")
    t = rapid.sample_times(0.001)
    assert np.linalg.norm(rapid.derivatives(t, 1), axis=1).max() == pytest.approx(
        LIMITS.rapid_speed
    )
    t = feed.sample_times(0.001)
    assert np.linalg.norm(feed.derivatives(t, 1), axis=1).max() == pytest.approx(0.02)


def test_the_run_managers_planner_accepts_the_program_path():
    """What RunManager.start will get: an approach to the program's start and a stop."""
    path = plan("G1 F1200 X10\nG3 X0 Y10 R10")
    run = plan_sinusoid(path, np.array([0.0, 0.0, -0.23]))
    times, points = run.sample(0.005)
    np.testing.assert_allclose(points[0], [0.0, 0.0, -0.23], atol=1e-12)
    np.testing.assert_allclose(points[-1], [0.0, 0.01, -0.24], atol=1e-9)
    speed, accel, jerk = path.peaks()
    sampled = np.linalg.norm(path.derivatives(path.sample_times(0.001), 1), axis=1).max()
    assert sampled <= speed * (1 + 1e-9)


SQUARE = "G1 F3000 X20\nY20\nX0\nY0"


def corners_of(text):
    segments = interpret(tokenize(text), START, (0.0, 0.0, 0.0)).segments
    return np.array([s.end_m for s in segments])


@pytest.mark.parametrize("tolerance_mm", [0.001, 0.05, 10.0])
def test_g64_blends_corners_within_its_tolerance(tolerance_mm):
    """Under G64 P the path does not stop at a corner, stays within P of it, and keeps
    the speed and acceleration limits; the jerk of a 90 deg blend is up to sqrt(2) J."""
    exact = plan(SQUARE)
    blended = plan(f"G64 P{tolerance_mm}\n" + SQUARE)
    assert blended.duration_s < exact.duration_s
    overlaps = np.array(blended.overlaps_s)
    assert (overlaps > 0).all()
    t = blended.sample_times(0.0005)
    p, v, a, j = blended.evaluate(t, (0, 1, 2, 3))
    corners = corners_of(SQUARE)[:-1]
    for corner, start in zip(corners, blended.start_s[1:], strict=True):
        during = (t >= start) & (t <= start + overlaps.max())
        deviation = np.linalg.norm(p[during] - corner, axis=1)
        assert deviation.max() <= tolerance_mm * 1e-3 * (1 + 1e-9)
        mid = start + 0.5 * overlaps[0]
        assert np.linalg.norm(blended.derivatives(np.array(mid), 1)) > 0  # no stop
    assert np.linalg.norm(v, axis=1).max() <= 0.05 * (1 + 1e-9)
    assert np.linalg.norm(a, axis=1).max() <= LIMITS.feed_accel * (1 + 1e-9)
    assert np.linalg.norm(j, axis=1).max() <= np.sqrt(2) * LIMITS.feed_jerk * (1 + 1e-9)
    np.testing.assert_allclose(p[-1], [0.0, 0.0, -0.24], atol=1e-15)


def test_a_blended_path_is_continuous_and_its_derivatives_agree():
    path = plan("G64 P1\nG1 F3000 X20\nG3 X30 Y10 I0 J10\nG1 Y30\nG0 X0")
    assert sum(path.overlaps_s) > 0
    dt = 1e-5
    t = np.linspace(0.001, path.duration_s - 0.001, 4001)
    for order in (1, 2):
        central = (path.derivatives(t + dt, order - 1) - path.derivatives(t - dt, order - 1)) / (
            2 * dt
        )
        scale = np.abs(path.derivatives(t, order)).max()
        np.testing.assert_allclose(central, path.derivatives(t, order), atol=2e-3 * scale)


def test_collinear_moves_under_g64_run_on_and_a_dwell_still_stops():
    path = plan("G64\nG1 F3000 X10\nX20\nG4 P0.1\nX30")
    assert path.overlaps_s[0] > 0 and path.overlaps_s[1:] == (0.0, 0.0)
    speed_at_x10 = np.linalg.norm(path.derivatives(np.array(path.start_s[1]), 1))
    assert speed_at_x10 > 0
    np.testing.assert_allclose(path.derivatives(path.start_s[2:3], 1), 0.0, atol=1e-15)


moves = st.lists(
    st.tuples(
        st.sampled_from(["G0", "G1", "G2", "G3", "G4"]),
        st.tuples(*[st.integers(-20, 20)] * 3),
        st.integers(100, 6000),  # feed [mm/min]
    ),
    min_size=1,
    max_size=6,
)


@settings(max_examples=40, deadline=None)
@given(moves, st.booleans())
def test_random_programs_pass_through_every_programmed_point(program, blend):
    """Under G61 the path is at each move's end when the next starts, at rest; in any mode
    it ends at the last point, never jumps between samples and its lines never go back."""
    lines = ["G64 P0.5" if blend else "G61", "G91"]
    for code, (x, y, z), feed in program:
        if code == "G4":
            lines.append("G4 P0.1")
        elif code in ("G2", "G3"):  # a half circle of radius |x| + 1 about a point on x
            r = abs(x) + 1
            lines.append(f"{code} X{2 * r} Y0 Z{z} I{r} J0 F{feed}")
        else:
            lines.append(f"{code} X{x} Y{y} Z{z} F{feed}")
    segments = interpret(tokenize("\n".join(lines)), START, (0.0, 0.0, 0.0)).segments
    if not segments:
        return
    path = plan_program(segments, LIMITS)
    t = path.sample_times(LIMITS.period_s)
    p = path.derivatives(t, 0)
    np.testing.assert_allclose(p[-1], segments[-1].end_m, atol=1e-12)
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    assert steps.max(initial=0) <= LIMITS.rapid_speed * LIMITS.period_s * (1 + 1e-9)
    assert (np.diff(path.line_at(t)) >= 0).all()
    if not blend:
        ends = path.start_s[1:]
        expected = np.array([s.end_m for s in segments[:-1]]).reshape(-1, 3)
        np.testing.assert_allclose(path.derivatives(ends, 0), expected, atol=1e-12)
        np.testing.assert_allclose(path.derivatives(ends, 1), 0.0, atol=1e-12)


def test_a_tick_late_by_more_than_a_short_line_still_meets_it():
    """A 200 ms stall crosses the 5 mm rapid (line 2) whole: no tick falls on it, yet the
    run source lists it among the lines met, in program order."""
    from app.runs.source import TrajectorySource

    path = plan("G4 P0.05\nG0 X5\nG4 P0.5\nG1 F600 X0", start=(0.0, 0.0, -0.24))
    rapid = path.end_s[1] - path.start_s[1]
    assert 0.0 < 0.05 + rapid < 0.2, rapid
    source = TrajectorySource(plan_sinusoid(path, np.array(START)))
    source.next(source.plan.approach_s + 1e-4)  # the first timed tick, on line 1
    seen = [source.program_line]
    source.next(0.2)  # late: past the rest of line 1 and the whole of line 2
    seen.append(source.program_line)
    while not source.finished:
        source.next(0.005)
        if source.program_line is not None:
            seen.append(source.program_line)
    assert 2 not in seen and seen[:2] == [1, 3]
    assert source.lines_met == [1, 2, 3, 4]
    assert path.lines_between(0.0, path.duration_s) == [1, 2, 3, 4]


def test_the_stats_list_a_line_met_without_samples_with_no_error():
    from app.runs.recorder import with_unsampled

    sampled = [{"line": 3, "samples": 4, "rmse_m": 1e-3, "max_m": 2e-3}]
    out = with_unsampled(sampled, [2, 3])
    assert out == [{"line": 2, "samples": 0, "rmse_m": None, "max_m": None}, sampled[0]]
    assert with_unsampled(sampled, []) == sampled


def test_a_line_met_without_samples_is_served_by_the_runs_api_model():
    """GET /api/runs served a 500 for such a line (null errors against float fields)."""
    from app.runs.recorder import with_unsampled
    from app.server.api.responses import ProgramStats

    sampled = [{"line": 3, "samples": 4, "rmse_m": 1e-3, "max_m": 2e-3}]
    stats = ProgramStats.model_validate({"lines": with_unsampled(sampled, [2, 3])})
    assert [(e.line, e.samples, e.rmse_m) for e in stats.lines] == [(2, 0, None), (3, 4, 1e-3)]

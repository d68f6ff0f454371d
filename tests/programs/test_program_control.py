"""A program's motion control (app/link/paths.py Playback): pause, single step, feed
override, M0 / M1, time left and run from a line, on the node's PathSource and the
station's TrajectorySource. Laws: a paused path's setpoint stays on the sampled path and
stands; at feed k the setpoint moves k times as fast as planned; a step stops exactly at
the line's end; an M0 stops exactly at its time; the acceleration a change of rate adds
stays within its bound; both sources play the same setpoints."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.control.errors import MotionRefused
from app.link.codec import decode, encode
from app.link.paths import EXTRA_ACCEL_M_S2, PathSource, SampledPath, feed_override
from app.programs.modal import interpret
from app.programs.planner import PlanLimits, plan_program
from app.programs.tokens import tokenize
from app.runs.source import TrajectorySource
from app.runs.trajectories import SinusoidParams, plan_sinusoid

PERIOD = 0.005
LIMITS = PlanLimits(0.5, 4.0, 100.0, 2.0, 50.0, 1e-5, PERIOD)
START = (0.0, 0.0, -0.24)
# lines 2-3 blended (G64: no stop at their corner), an M0 on line 4, an M1 on line 6
PROGRAM = "G21 G90 G64 P0.5 F1200\nG1 X20\nG1 Y20\nM0\nG1 X0\nM1\nG1 Y0\nM2"
M0_LINE, M1_LINE = 4, 6


def _twin(text: str = PROGRAM, start=START) -> TrajectorySource:
    path = plan_program(interpret(tokenize(text), start, (0.0, 0.0, 0.0)).segments, LIMITS)
    return TrajectorySource(plan_sinusoid(path, np.asarray(start, dtype=float)))


def _node(text: str = PROGRAM) -> PathSource:
    """The node's source of the program, from its samples as they cross the link."""
    sampled = _twin(text).sampled(PERIOD)
    return PathSource(decode(SampledPath, json.loads(encode(sampled))), "run-1")


def _distance_to_polyline(point: np.ndarray, points: np.ndarray) -> float:
    a, b = points[:-1], points[1:]
    ab = b - a
    length2 = np.maximum((ab * ab).sum(axis=1), 1e-300)
    u = np.clip(((point - a) * ab).sum(axis=1) / length2, 0.0, 1.0)
    return float(np.linalg.norm(a + u[:, None] * ab - point, axis=1).min())


def _play_until(source, done, limit: int = 20_000) -> list:
    out = []
    for _ in range(limit):
        out.append(source.next(PERIOD))
        if done(source):
            return out
    raise AssertionError("never reached")


@settings(max_examples=25, deadline=None)
@given(pause_tick=st.integers(5, 100), override=st.sampled_from([0.1, 0.35, 0.6, 1.0]))
def test_a_paused_program_decelerates_along_its_path_and_stands_on_it(pause_tick, override):
    node = _node()
    node.playback.steer("feed", override=override)
    path = node.path
    for _ in range(pause_tick):
        node.next(PERIOD)
    node.playback.steer("pause")
    goals = [s.goal_m for s in _play_until(node, lambda s: s.playback.rate == 0.0)]
    standing_t = node.t_s
    goals += [node.next(PERIOD).goal_m for _ in range(50)]  # it stands: time and point
    assert node.t_s == standing_t and node.feed_state.paused == "paused"
    for goal in goals:
        assert _distance_to_polyline(goal, path.points_m) < 1e-12
    np.testing.assert_array_equal(goals[-1], goals[-50])
    # what the change of rate adds to the planned acceleration stays within its bound
    # (plus the planned path's own, at most 2 m/s^2 here, and one tick's rounding)
    accel = np.linalg.norm(np.diff(np.array(goals), 2, axis=0), axis=1) / PERIOD**2
    assert accel.max() <= 2.0 + EXTRA_ACCEL_M_S2 + 0.2


@pytest.mark.parametrize("override", [0.1, 0.25, 0.5, 0.8])
def test_at_a_feed_override_the_tool_moves_k_times_as_fast_as_planned(override):
    twin = _twin()
    twin.start_play["override"] = override
    plan = twin.plan
    goals, times = [], []
    while twin.t_s < 0.45:  # line 2, past the rate's ramp
        goals.append(twin.next(PERIOD).goal_m)
        times.append(twin.t_s)
    ramp_ticks = int((1.0 - override) / (twin.playback.slew * PERIOD)) + 2
    for i in range(ramp_ticks, len(goals) - 1):
        speed = np.linalg.norm(goals[i + 1] - goals[i]) / PERIOD
        mid = 0.5 * (times[i] + times[i + 1])
        planned = float(np.linalg.norm(plan.params.derivatives(np.array(mid), 1)))
        assert speed == pytest.approx(override * planned, abs=2e-3 * override)
    # time left: the path time left at the override
    left = twin.feed_state.time_left_s
    assert left == pytest.approx((plan.duration_s - twin.t_s) / override)


def test_a_single_step_stops_exactly_at_the_lines_end_then_resume_goes_on():
    node = _node()
    spans = node.path.spans
    for _ in range(10):  # on line 2
        node.next(PERIOD)
    assert node.program_line == 2
    state = node.playback.steer("step")
    assert state.stop_line == 2 and state.paused is None
    _play_until(node, lambda s: s.playback.rate == 0.0)
    line2_end = float(spans[spans[:, 0] == 2][0, 2])
    assert node.t_s == line2_end  # exactly: a blended corner, braked for in time
    np.testing.assert_allclose(node.next(PERIOD).goal_m, node.path.point_at(line2_end))
    assert node.feed_state.paused == "single step: stopped at the end of line 2"
    assert node.program_line == 2  # the line stays
    node.playback.steer("resume")
    _play_until(node, lambda s: s.program_line == 3)


def test_a_step_while_braking_past_a_lines_end_stops_at_the_next_one():
    node = _node()
    spans = node.path.spans
    line2_end = float(spans[spans[:, 0] == 2][0, 2])
    braking = 1.0 / (2.0 * node.playback.slew)  # path time to stand from 100 %
    _play_until(node, lambda s: s.t_s > line2_end - 0.3 * braking)
    node.playback.steer("step")  # too late for line 2's end: line 3's (at rest, M0 next)
    _play_until(node, lambda s: s.playback.rate == 0.0)
    assert node.t_s == float(spans[spans[:, 0] == 3][0, 2])
    assert node.feed_state.stop_line == 3


@pytest.mark.parametrize("optional_stop", [False, True])
def test_m0_stops_exactly_at_its_line_and_m1_only_with_the_optional_stop(optional_stop):
    node = _node()
    node.playback.steer("optional_stop", on=optional_stop)
    pauses = {int(line): float(t) for t, line, _ in node.path.pauses}
    _play_until(node, lambda s: s.playback.rate == 0.0)
    assert node.t_s == pauses[M0_LINE] and node.program_line == M0_LINE
    assert node.feed_state.paused == f"M0 at line {M0_LINE}: press Resume"
    before = node.t_s
    for _ in range(100):  # it waits for Resume
        node.next(PERIOD)
    assert node.t_s == before
    node.playback.steer("resume")
    stood = []
    while not node.finished:
        node.next(PERIOD)
        if node.playback.rate == 0.0:
            stood.append((node.t_s, node.program_line, node.feed_state.paused))
            node.playback.steer("resume")
    if optional_stop:
        why = f"M1 (optional stop) at line {M1_LINE}: press Resume"
        assert stood == [(pauses[M1_LINE], M1_LINE, why)]
    else:
        assert not stood


def test_the_node_and_the_station_twin_play_the_same_setpoints_under_the_same_commands():
    twin, node = _twin(), _node()
    commands = {30: ("feed", {"override": 0.4}), 60: ("pause", {}), 140: ("resume", {})}
    commands |= {200: ("step", {}), 400: ("resume", {}), 420: ("feed", {"override": 1.0})}
    for tick in range(1500):
        if tick in commands:
            action, values = commands[tick]
            assert twin.playback.steer(action, **values) == node.playback.steer(action, **values)
        want, got = twin.next(PERIOD), node.next(PERIOD)
        # between samples the node interpolates linearly: within a dt^2 / 8 (2 m/s^2)
        np.testing.assert_allclose(got.goal_m, want.goal_m, atol=1e-5)
        assert node.t_s == pytest.approx(twin.t_s, abs=1e-12)
        if twin.finished:
            break
        assert (node.program_line, node.feed_state.paused) == (
            twin.program_line,
            twin.feed_state.paused,
        )
        if node.playback.rate == 0.0 and node.feed_state.paused.startswith("M0"):
            twin.playback.steer("resume"), node.playback.steer("resume")


@pytest.mark.parametrize("value", [0.0, 0.05, 1.01, 2.0, float("nan"), True, "1"])
def test_a_feed_override_outside_10_to_100_percent_is_refused_naming_it(value):
    node = _node()
    with pytest.raises(ValueError, match="override"):
        node.playback.steer("feed", override=value)
    assert node.playback.override == 1.0
    assert feed_override(0.1) == 0.1 and feed_override(1) == 1.0


def test_a_run_that_is_not_a_program_cannot_step_but_pauses_on_its_path():
    params = SinusoidParams(amplitude_m=(0.01, 0.02, 0.0), duration_s=1.0)
    source = TrajectorySource(plan_sinusoid(params, np.array(START)))
    path = source.sampled(PERIOD)
    node = PathSource(path, "s")
    with pytest.raises(MotionRefused, match="step: this run is not a program"):
        node.playback.steer("step")
    for _ in range(40):
        node.next(PERIOD)
    node.playback.steer("pause")
    goals = [s.goal_m for s in _play_until(node, lambda s: s.playback.rate == 0.0)]
    assert max(_distance_to_polyline(g, path.points_m) for g in goals) < 1e-12
    assert not node.finished


def test_run_from_a_line_starts_at_that_lines_first_segment():
    path = _twin().plan.params
    from_line_5 = path.from_line(5)
    assert from_line_5.segments[0].line == 5
    np.testing.assert_allclose(from_line_5.derivatives(np.array(0.0), 0), [0.02, 0.02, -0.24])
    assert from_line_5.duration_s == pytest.approx(path.duration_s - path.start_s[3])
    assert path.from_line(1).segments == path.segments
    with pytest.raises(ValueError, match="start_line: no move, dwell or pause on line 9"):
        path.from_line(9)


def test_m1_reads_as_an_optional_pause():
    segments = interpret(tokenize(PROGRAM), START, (0.0, 0.0, 0.0)).segments
    pauses = [(s.line, s.optional) for s in segments if s.kind == "pause"]
    assert pauses == [(M0_LINE, False), (M1_LINE, True)]


def test_a_program_with_no_m0_crosses_the_link_and_plays_to_its_end():
    node = _node("G21 G91 F1200\nG1 X5\nG1 Y5\nM2")
    assert node.path.pauses.shape == (0, 3)
    _play_until(node, lambda s: s.finished)
    assert node.feed_state.paused is None

"""The A word: the wrist's angle in degrees (a rotary axis as LinuxCNC's A), with a wrist.

Laws: A is absolute under G90 and added under G91, never scaled by G20 or shifted by G54;
phi runs linearly with the tip along a G1 and within the wrist's speed on every sample; a
turn of the wrist alone takes at least its angle over the wrist's speed; A outside the
wrist's limits, and any A without a wrist, is refused naming its line and word; the
platform's velocity and acceleration with a turning tool are the finite differences of
its points; a run plays the program's phi.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.config import load_settings
from app.control.commands import CommandContext
from app.programs import verify
from app.programs.check import check_program
from app.programs.errors import ProgramError
from app.programs.modal import interpret
from app.programs.tokens import Word, tokenize, tokenize_line
from app.runs.source import TrajectorySource
from app.runs.trajectories import plan_sinusoid

WRIST = {"enabled": True, "min_angle_rad": -1.0, "max_angle_rad": 2.0, "max_speed_rad_s": 2.0}
LIMITS = (-1.0, 2.0)
START = (0.0, 0.0, -0.22)
ORIGIN = (0.0, 0.0, -0.22)


@pytest.fixture(scope="module")
def settings():
    return load_settings(wrist=WRIST, tool={"offset_m": [0.02, 0.0, -0.03]})


def segments(text: str, phi0: float = 0.0, wrist=LIMITS):
    return interpret(tokenize(text), START, ORIGIN, phi0, wrist).segments


def test_a_is_read_as_a_word() -> None:
    line = tokenize_line("g1 a-12.5 (turn) X3", 4)
    assert line.words[1] == Word("A", -12.5, "A-12.5")
    assert line.number == 4


def test_a_is_absolute_under_g90_added_under_g91_in_degrees_whatever_the_units() -> None:
    program = "G90 G1 F600 X1 A30\nG91 A10\nG20 X0.1 A-5\nG90 G0 A0"
    ends = [s.phi_end_rad for s in segments(program, phi0=0.2)]
    expected = [30.0, 40.0, 35.0, 0.0]
    np.testing.assert_allclose(ends, np.radians(expected), rtol=0, atol=1e-15)
    starts = [s.phi_start_rad for s in segments(program, phi0=0.2)]
    assert starts[0] == 0.2 and starts[1:] == ends[:-1]  # each move from the last
    # a line without A keeps phi; a dwell and a pause keep it too
    kept = segments("G1 F600 A20\nG1 X2\nG4 P0.1\nM0")
    assert {s.phi_start_rad for s in kept[1:]} == {s.phi_end_rad for s in kept[1:]}
    assert kept[-1].phi_end_rad == pytest.approx(math.radians(20))


def test_a_turn_alone_is_a_segment_fed_in_degrees_per_minute() -> None:
    (turn,) = segments("G1 F120 A45")
    assert turn.kind == "linear" and turn.curve().length == 0.0
    assert turn.feed_rad_s == pytest.approx(math.radians(120) / 60.0)
    assert turn.distance == pytest.approx(math.radians(45))
    assert segments("G1 F120 A0") == []  # no travel and no turn: nothing


@pytest.mark.parametrize(
    ("program", "line", "word"),
    [
        ("G1 F100 X1\nG1 A120", 2, "A120"),  # 2.09 rad > 2.0
        ("G91\nG1 F100 A100\nA-100\nA-100", 4, "A-100"),  # incremental: -100 deg < -57.3
    ],
)
def test_a_outside_the_wrist_s_limits_is_refused_at_its_line_and_word(program, line, word):
    with pytest.raises(ProgramError) as refused:
        segments(program)
    assert (refused.value.line, refused.value.word) == (line, word)
    assert "outside its limits [-57.3, 114.6] deg" in str(refused.value)


def test_a_is_refused_without_a_wrist_and_on_a_dwell() -> None:
    with pytest.raises(ProgramError) as refused:
        segments("G21\nG1 F100 X1 A5", wrist=None)
    assert (refused.value.line, refused.value.word) == (2, "A5")
    assert "the wrist axis is not configured" in refused.value.reason
    with pytest.raises(ProgramError) as refused:
        check_program("G21\nG1 F100 X1 A5", load_settings())
    assert (refused.value.line, refused.value.word) == (2, "A5")
    with pytest.raises(ProgramError, match="G4 takes P"):
        segments("G4 P1 A5")


def test_check_refuses_a_beyond_the_wrist_naming_line_and_word(settings) -> None:
    with pytest.raises(ProgramError) as refused:
        check_program("G21 G90\nG1 F600 X5\nG1 X6 A130", settings)
    assert (refused.value.line, refused.value.word) == (3, "A130")


def test_phi_is_linear_along_a_g1_and_within_the_wrist_speed(settings) -> None:
    # a fast feed: the wrist's 90 deg over 10 mm would need 17 rad/s at F6000, so the
    # wrist's speed sets the pace
    checked = check_program("G21 G90\nG1 F6000 X10 A90\nG1 X-5", settings, start_phi_rad=0.1)
    report, path = checked.report, checked.path
    assert report.ok, report.violations
    times = path.sample_times(report.period_s)
    phi = path.phi_at(times)
    points = path.evaluate(times, (0,))[0]
    on_first = path.line_at(times) == 2
    start, end = path.segments[0].start_m, path.segments[0].end_m
    length = float(np.linalg.norm(np.subtract(end, start)))
    travelled = np.linalg.norm(points[on_first] - start, axis=1) / length
    np.testing.assert_allclose(phi[on_first], 0.1 + (math.pi / 2 - 0.1) * travelled, atol=1e-9)
    assert phi[0] == pytest.approx(0.1) and phi[-1] == pytest.approx(math.pi / 2)
    steps = np.abs(np.diff(phi))
    assert steps.max() <= 2.0 * report.period_s * (1 + 1e-9)
    assert steps.max() >= 0.9 * 2.0 * report.period_s  # the wrist is what limits it
    assert path.start_s[1] >= (math.pi / 2 - 0.1) / 2.0
    # the second line does not turn it
    assert np.ptp(phi[path.line_at(times) == 3]) == 0.0


def test_a_turn_alone_takes_at_least_its_angle_over_the_wrist_speed(settings) -> None:
    checked = check_program("G0 A100\nG1 F60000 A-50", settings)  # F: 1000 deg/s asked
    path = checked.path
    assert checked.report.ok and checked.report.length_m == 0.0
    assert path.start_s[1] >= math.radians(100) / 2.0
    assert path.duration_s - path.start_s[1] >= math.radians(150) / 2.0
    times = path.sample_times(checked.report.period_s)
    points, phi = path.evaluate(times, (0,))[0], path.phi_at(times)
    assert np.ptp(points, axis=0).max() == 0.0  # the tip stays where it is
    assert np.abs(np.diff(phi)).max() <= 2.0 * checked.report.period_s * (1 + 1e-9)
    assert path.phi_peak_speed() <= 2.0


def test_the_platform_of_a_turning_tool_moves_as_its_finite_differences(settings) -> None:
    gate = CommandContext.from_settings(settings).gate
    dt = 1e-4
    t = np.arange(0.0, 0.5, dt)
    tip = np.stack([0.01 * np.sin(3 * t), 0.02 * t, -0.22 + 0.0 * t], axis=1)
    tip_v, tip_a = (
        np.gradient(tip, dt, axis=0),
        np.gradient(np.gradient(tip, dt, axis=0), dt, axis=0),
    )
    phi = 0.7 * np.sin(5 * t)
    wrist = (phi, 3.5 * np.cos(5 * t), -17.5 * np.sin(5 * t))
    p, pd, pdd = verify._platform(gate, tip, tip_v, tip_a, wrist)
    np.testing.assert_allclose(p, gate.platform(tip, phi), atol=1e-15)
    inner = slice(5, -5)
    fd_v = np.gradient(p, dt, axis=0)
    fd_a = np.gradient(fd_v, dt, axis=0)
    np.testing.assert_allclose(pd[inner], fd_v[inner], atol=1e-6)
    np.testing.assert_allclose(pdd[inner], fd_a[inner], atol=1e-3)
    assert np.abs(pd - tip_v).max() > 0.05  # the turning offset adds speed: not a no-op


def test_a_run_plays_the_program_s_phi(settings) -> None:
    checked = check_program("G21 G90\nG1 F600 X5 A30\nG0 A-20", settings, start_m=START)
    path = checked.path
    assert path.moves_wrist
    plan = plan_sinusoid(path, np.asarray(START))
    source = TrajectorySource(plan)
    dt = checked.report.period_s
    seen = []
    while not source.finished:
        setpoint = source.next(dt)
        seen.append((source.t_s, setpoint.phi_rad))
    t, phi = np.array(seen).T
    np.testing.assert_allclose(phi, path.phi_at(np.clip(t - plan.approach_s, 0, path.duration_s)))
    assert phi[-1] == pytest.approx(math.radians(-20))
    # without an A word the run leaves the wrist to the loop
    plain = check_program("G21 G90\nG1 F600 X5", settings, start_m=START).path
    assert not plain.moves_wrist
    assert TrajectorySource(plan_sinusoid(plain, np.asarray(START))).next(dt).phi_rad is None


def test_the_check_names_a_wrist_sample_too_fast_or_beyond_its_limits(settings) -> None:
    from app.programs.check import verify_limits

    gate = CommandContext.from_settings(settings).gate
    n, dt = 6, 0.005
    times = np.arange(n) * dt
    points = np.tile(START, (n, 1))
    zeros = np.zeros((n, 3))
    phi = np.array([0.0, 0.0, 0.5, 0.5, 2.2, 2.2])  # a jump on line 2, past 2.0 on line 3
    lines = np.array([1, 1, 2, 2, 3, 3])
    wrist = (phi, np.zeros(n), np.zeros(n))
    result = verify.verify_path(
        gate,
        verify_limits(settings),
        times,
        lines,
        points,
        zeros,
        zeros,
        np.full(3, np.nan),
        dt,
        wrist,
    )
    found = {(v.line, v.kind) for v in result.violations}
    assert {(2, "wrist_speed"), (3, "wrist_speed"), (3, "wrist_limit")} <= found
    assert not any(v.line == 1 for v in result.violations)
    (limit,) = [v for v in result.violations if v.kind == "wrist_limit"]
    # 2.2 rad (126.05 deg), 0.2 rad (11.46 deg) past the upper limit 2.0 rad (114.59 deg)
    assert limit.message == (
        "the wrist reaches 126.1 deg, 11.5 deg beyond its upper limit 114.6 deg"
    )
    (jump,) = [v for v in result.violations if (v.line, v.kind) == (2, "wrist_speed")]
    most = gate.wrist_max_step_rad / dt  # 0.5 rad in one 5 ms sample: 100 rad/s
    assert jump.message == (
        f"the wrist turns at 100.00 rad/s, {100.0 - most:.2f} rad/s over its limit {most:.2f} rad/s"
    )
    # on line 3 the angle is the first cause, the jump that took it there (and the joints'
    # step: the tool turns about the platform) folded under it
    folded = verify.fold(result.violations)
    line3 = [(k, v) for k, v in enumerate(folded) if v.line == 3]
    (k, first), *rest = line3
    assert (first.kind, first.folded_under) == ("wrist_limit", None)
    assert ("wrist_speed", k) in {(v.kind, v.folded_under) for _, v in rest}

"""The whole check: a program refused at the right line for the right reason, all
violations collected, a passing program's report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.config import load_settings
from app.programs.check import check_program
from app.programs.errors import ProgramError

GOOD = "G21 G90\nG1 F1200 X0 Y0 Z-220\nG2 X10 Y0 I5 J0\nG4 P0.2\nG0 X0\nM2"


@pytest.fixture(scope="module")
def settings():
    return load_settings()


def kinds_by_line(report):
    out: dict[int, set[str]] = {}
    for v in report.violations:
        out.setdefault(v.line, set()).add(v.kind)
    return out


def test_a_program_inside_the_limits_passes(settings):
    checked = check_program(GOOD, settings)
    report = checked.report
    assert report.ok and report.violations == []
    assert report.duration_s == pytest.approx(checked.path.duration_s)
    assert report.length_m == pytest.approx(0.02 + 0.005 * np.pi + 0.01)
    assert report.samples == len(checked.path.sample_times(report.period_s))
    assert 0 < report.worst_torque_ratio < settings.programs.max_torque_ratio
    assert report.worst_dexterity >= settings.limits.min_dexterity
    assert 0 < report.peak_joint_speed_rad_s < settings.limits.joint_speed_rad_s
    np.testing.assert_allclose(report.path_m[0], settings.programs.start_m)
    np.testing.assert_allclose(report.path_m[-1], [0.0, 0.0, -0.22], atol=1e-12)
    json.dumps(report.to_dict(), allow_nan=False)  # JSON as it stands
    # each drawn point carries the line the planned path is on at that point
    assert len(report.path_lines) == len(report.path_m)
    times = checked.path.sample_times(report.period_s)
    points = checked.path.evaluate(times, (0,))[0]
    lines = checked.path.line_at(times)
    for point, line in zip(report.path_m, report.path_lines, strict=True):
        at = np.flatnonzero(np.all(np.isclose(points, point, atol=1e-12), axis=1))
        assert line in set(lines[at].tolist())
    assert report.path_lines == sorted(report.path_lines)  # in program order


def test_leaving_the_workspace_is_refused_at_its_line(settings):
    """Lines 1-3 stay well inside; line 4 climbs through the ceiling (z_max -60 mm)."""
    text = "G90 G1 F1200 Z-220\nX20\nX0\nZ-40\nZ-220"
    checked = check_program(text, settings)
    report = checked.report
    assert not report.ok
    assert min(kinds_by_line(report)) == 4
    ceiling = [v for v in report.violations if v.kind == "ceiling"]
    assert [v.line for v in ceiling] == [4, 5]  # up on line 4, back down on 5
    first = ceiling[0]
    assert first.point_m[2] > settings.limits.z_max_m
    # the point is the path's own point at that time, and the previous sample was below
    np.testing.assert_allclose(checked.path.derivatives(np.array(first.t_s), 0), first.point_m)
    before = checked.path.derivatives(np.array(first.t_s - report.period_s), 0)
    assert before[2] <= settings.limits.z_max_m
    assert "ceiling" in first.message and "mm" in first.message


def test_a_move_too_fast_for_the_joints_is_refused_at_its_line(settings):
    slow = load_settings(limits={"joint_speed_rad_s": 1.0})
    text = "G90 G1 F600 X10 Z-220\nG1 F12000 X-30\nG1 F600 X0"  # 1.14 rad/s on line 2
    report = check_program(text, slow).report
    assert {v.line for v in report.violations} == {2}
    (speed,) = [v for v in report.violations if v.kind == "joint_speed"]
    assert "over the speed limit 1.00 rad/s" in speed.message
    # the value reached and by how much: the peak (the line's worst), less the limit
    reached = f"turns at {report.peak_joint_speed_rad_s:.2f} rad/s, "
    assert reached in speed.message
    assert f"{report.peak_joint_speed_rad_s - 1.0:.2f} rad/s over" in speed.message
    assert report.peak_joint_speed_rad_s > 1.0
    # the same program at the default limit passes: the speed is what failed
    assert check_program(text, settings).report.ok


def test_every_failing_check_is_reported_not_only_the_first(settings):
    heavy = load_settings(programs={"payload_kg": 50.0, "joint_acceleration_rad_s2": 1.0})
    report = check_program("G90 G1 F1200 Z-220\nX10", heavy).report
    assert {"torque", "joint_acceleration"} <= {v.kind for v in report.violations}
    assert {v.line for v in report.violations} == {1, 2}
    # by move: line by line, each line's first cause first, the others folded under it
    lines = [v.line for v in report.violations]
    assert lines == sorted(lines)
    for k, v in enumerate(report.violations):
        if v.folded_under is None:
            assert k == 0 or report.violations[k - 1].line != v.line
        else:
            assert report.violations[v.folded_under].line == v.line


def test_a_work_offset_and_start_are_used(settings):
    report = check_program(
        "G90 G1 F1200 X0 Y0 Z0", settings, start_m=(0.0, 0.0, -0.2), work_offset_m=(0.01, 0, -0.22)
    ).report
    assert report.ok
    np.testing.assert_allclose(report.path_m[-1], [0.01, 0.0, -0.22], atol=1e-12)


def test_an_unreadable_program_raises_with_its_line(settings):
    with pytest.raises(ProgramError) as caught:
        check_program("G21\nG1 F100 X1\nG1 A5", settings)
    assert (caught.value.line, caught.value.word) == (3, "A5")


def test_a_program_over_the_line_limit_is_refused(settings):
    short = load_settings(programs={"max_lines": 3})
    with pytest.raises(ProgramError, match="max_lines"):
        check_program("G21\n" * 4, short)
    for newline in ("\r", "\r\n"):  # lines counted as the tokenizer counts them
        with pytest.raises(ProgramError, match="max_lines"):
            check_program(newline * 3 + "G21", short)


def test_a_program_that_does_not_move_is_checked_where_the_tool_is(settings):
    report = check_program("(nothing)\nM2", settings).report
    assert report.ok and report.duration_s == 0 and report.samples == 1


def test_the_torque_line_is_the_twins_servo():
    """The check's torque-speed line is the XM430-W210 the simulator's servos model."""
    from app.programs.check import verify_limits
    from hardware.sim.xm430 import RPM, XM430_W210

    servo = verify_limits(load_settings()).servo
    assert servo.stall_nm == XM430_W210.stall_torque_nm
    assert servo.no_load_rpm * RPM == pytest.approx(XM430_W210.no_load_speed_rad_s)


def test_the_singularity_margin_is_checked_on_every_line(settings):
    text = "G90 G1 F1200 Z-220\nX10\nG4 P0.1\nG0 X0"
    assert check_program(text, settings).report.ok
    strict = load_settings(limits={"min_dexterity": 0.99})
    report = check_program(text, strict).report
    assert {v.line for v in report.violations if v.kind == "singularity"} == {1, 2, 3, 4}
    assert report.worst_dexterity < 0.99


def test_a_linear_delta_is_checked_without_a_torque_model():
    linear = load_settings(robot={"type": "linear"})
    report = check_program("G1 F600 Z-300", linear, start_m=(0.0, 0.0, -0.3)).report
    assert report.worst_torque_ratio is None
    assert all(v.kind != "torque" for v in report.violations)


def test_a_torque_no_servo_can_give_is_said_in_words_not_inf(settings):
    """Past the servo's no-load speed it gives no torque: the ratio is infinite, and the
    message says why instead of printing inf."""
    # from a start given in metres where mm were meant (a user's trial): out of reach, and
    # the branch followed back in whips a joint past the servo's no-load speed
    report = check_program(
        "G21 G90\nG1 F1200 X0 Y0 Z-220\nM2", settings, start_m=(0.0, 0.0, -0.00024)
    ).report
    torque = [v for v in report.violations if v.kind == "torque"]
    assert torque, report.violations
    assert all("inf" not in v.message for v in report.violations)
    assert any("gives none" in v.message for v in torque)


def _dwell_program(dwell_s: float) -> str:
    """A move to (0, 0, -220) mm (line 2), a dwell of ``dwell_s`` (line 3), a move (line 4)."""
    return f"G21 G90\nG1 F1200 X0 Y0 Z-220\nG4 P{dwell_s:g}\nX5\nM2"


def test_a_program_longer_than_a_run_may_be_fails_its_check_as_the_run_refuses_it():
    """A check never says ok to what POST /api/programs/run refuses: a program longer than
    runs.max_samples (a run's log) gets a run_duration violation at the line in execution
    when the log would be full, in the words the run's refusal uses (an attacker's trial
    had a 922 s program pass its check, then the run refuse it)."""
    settings = load_settings(runs={"max_samples": 2000})  # 10 s at 200 Hz
    text = _dwell_program(15.0)
    report = check_program(text, settings).report
    assert not report.ok
    [violation] = report.violations  # nothing else is wrong with it
    assert (violation.line, violation.kind) == (3, "run_duration")  # dwelling at 10 s
    assert "runs.max_samples = 2000" in violation.message and "(10 s)" in violation.message
    assert violation.t_s == pytest.approx(2000 * report.period_s)
    np.testing.assert_allclose(violation.point_m, [0.0, 0.0, -0.22], atol=1e-12)
    with pytest.raises(ProgramError) as refused:  # what the run's check says, unchecked
        check_program(text, settings, for_run=True)
    assert (refused.value.line, refused.value.word) == (violation.line, "")
    assert str(refused.value) == f"line {violation.line}: {violation.message}"
    assert check_program(text, load_settings()).report.ok  # within the default 750 s


# the moves take 1.33 s: the program lasts the run limit (10 s) with a dwell of 8.67 s
@pytest.mark.parametrize("dwell_s", [8.0, 8.66, 8.665, 8.67, 8.675, 9.0])
def test_the_check_refuses_a_run_exactly_when_the_run_manager_would(dwell_s):
    """Around the limit: a run_duration violation iff the run manager's own count of the
    run's loop periods (approach, program, stop; PlannedRun.samples) is over the limit."""
    from app.runs.trajectories import plan_sinusoid

    settings = load_settings(runs={"max_samples": 2000})
    checked = check_program(_dwell_program(dwell_s), settings)
    report = checked.report
    plan = plan_sinusoid(checked.path, np.asarray(report.start_m))
    over = plan.samples(report.period_s) > settings.runs.max_samples
    assert ("run_duration" in {v.kind for v in report.violations}) == over
    assert report.ok == (not over)

"""The dry run: a checked program's path played on a headless twin, its predicted error
per line; too long a program refused before any physics."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from app.config import load_settings
from app.programs.check import check_program
from app.programs.dry_run import DryRunRefused, dry_run, line_errors

CIRCLE = Path(__file__).resolve().parents[2] / "examples" / "circle.ngc"


@pytest.fixture(scope="module")
def settings():
    return load_settings()


@pytest.fixture(scope="module")
def circle(settings):
    checked = check_program(CIRCLE.read_text(), settings)
    assert checked.report.ok
    return checked, dry_run(checked, settings)


def test_line_errors_are_the_error_magnitude_grouped_by_line_in_order():
    error = np.array([[3e-3, 4e-3, 0.0], [0.0, 0.0, 0.0], [1e-3, 0.0, 0.0], [0.0, 0.0, 0.0]])
    first, second = line_errors(np.array([7, 7, 3, 3]), error)
    assert (first.line, first.samples, second.line, second.samples) == (7, 2, 3, 2)
    assert first.rmse_m == pytest.approx(math.sqrt(25e-6 / 2)) and first.max_m == 5e-3
    assert second.rmse_m == pytest.approx(math.sqrt(1e-6 / 2)) and second.max_m == 1e-3


@pytest.mark.slow
def test_a_circle_has_a_finite_small_error_on_each_of_its_motion_lines(settings, circle):
    checked, result = circle
    assert result.ok is True and result.duration_s == checked.path.duration_s
    motion_lines = [s.line for s in checked.path.segments]  # in order, each once here
    assert [e.line for e in result.lines] == motion_lines
    ticks = math.ceil(checked.path.duration_s * settings.loop.rate_hz - 1e-9)
    assert sum(e.samples for e in result.lines) == ticks  # every tick of the path, once
    for entry in result.lines:
        assert math.isfinite(entry.rmse_m) and math.isfinite(entry.max_m)
        assert 0.0 < entry.rmse_m <= entry.max_m * (1 + 1e-9) <= result.max_m * (1 + 1e-9)
        assert entry.max_m < 0.02  # the servos lag by millimetres, not centimetres
    assert all(0.0 < v < 0.01 for v in result.rmse_m)
    # the error as a magnitude over all ticks: its mean square is the axes' sum
    total = sum(e.rmse_m**2 * e.samples for e in result.lines) / ticks
    assert total == pytest.approx(sum(v**2 for v in result.rmse_m), rel=1e-9)


@pytest.mark.slow
def test_feedforward_predicts_less_error_on_the_arc(settings, circle):
    """Commanding the point ahead makes up for the servos' position lag (thesis ch. 6)."""
    checked, plain = circle
    ahead = dry_run(checked, settings, feedforward=True)
    arc = {e.line: e for e in plain.lines}[5], {e.line: e for e in ahead.lines}[5]
    assert arc[1].rmse_m < arc[0].rmse_m


@pytest.mark.slow
def test_a_failing_program_is_played_as_the_loop_would_hold_it(settings):
    """Where the gate refuses a point the twin holds (as the live loop does): the error
    grows there but stays finite, and the result says the check failed."""
    checked = check_program("G21 G90\nG1 F6000 X0 Y0 Z-200\nZ-70\nZ-200\nM2", settings)
    assert not checked.report.ok
    result = dry_run(checked, settings)
    assert result.ok is False and [e.line for e in result.lines] == [2, 3, 4]
    assert all(math.isfinite(e.max_m) for e in result.lines)
    refused_line = {e.line: e for e in result.lines}[3]
    assert refused_line.max_m > {e.line: e for e in result.lines}[2].max_m


@pytest.mark.slow
def test_too_long_a_program_is_refused_naming_the_limit():
    settings = load_settings(programs={"dry_run_max_s": 2.0})
    checked = check_program("G4 P2.5\nM2", settings)
    with pytest.raises(DryRunRefused, match=r"programs\.dry_run_max_s") as refused:
        dry_run(checked, settings)
    assert "2.5 s" in str(refused.value)
    assert dry_run(check_program("G4 P1.5\nM2", settings), settings).lines[0].line == 1

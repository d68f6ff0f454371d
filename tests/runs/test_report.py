"""The report figure on synthetic runs: words and units, scored part only, broken lines at
missing ticks, PNG and vector PDF."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from app.runs import describe
from app.runs.recorder import run_stats
from app.runs.report import break_gaps, report_figure, report_lines, scored_mask, write_report
from app.runs.run import Run
from app.runs.stats import error_stats
from tests.support.saved_runs import (
    CONDITIONS,
    PERIOD_S,
    SINUSOID,
    SKIP_S,
    UNHEALTHY,
    synthetic_rows,
)


def run_of(tmp_path: Path, kind: str = "sinusoid", params: dict | None = None) -> Run:
    return Run("20260101-120000-abcd", kind, params or SINUSOID, CONDITIONS, tmp_path)


def texts_of(figure) -> str:
    texts = [t.get_text() for t in figure.texts]
    texts += [a.get_title() for a in figure.axes] + [a.get_ylabel() for a in figure.axes]
    return " ".join(texts)  # wrapped lines break at spaces


@pytest.mark.slow
def test_report_states_the_test_its_parameters_the_loop_and_the_verdict(tmp_path):
    rows = synthetic_rows()
    stats = {**run_stats(rows, SKIP_S, PERIOD_S), "health": UNHEALTHY}
    lines = report_lines(run_of(tmp_path), stats, None)
    figure = report_figure(rows, lines, stats, SKIP_S, PERIOD_S)
    try:
        text = texts_of(figure)
    finally:
        plt.close(figure)
    for expected in (
        "amplitude 50 / 50 / 80 mm",
        "frequency 1 / 1 / 2 Hz",
        "phase 0 / 90 / 0°",
        "offset 0 / 0 / −240 mm",
        "10 s",
        "feed-forward on, lead 20 ms",
        "141 Hz (target 50 Hz)",
        "p99 12.5",
        "worst 318 ms",
        "overruns 12 (2.1 %)",
        "longest gap 318 ms",
        "stale feedback 84 ticks",
        "NOT HEALTHY",
        "a gap of 318 ms between ticks",
    ):
        assert expected in text, (expected, text)
    for repr_ in ("True", "False", "None", "nan", "(0.0", "[0.05"):
        assert repr_ not in text, (repr_, text)
    x_rmse_mm = stats["tracking"]["x"]["rmse_m"] * 1e3
    assert f"RMSE {describe.number(x_rmse_mm)} mm" in text


def test_a_healthy_run_and_one_without_a_health_record_say_so(tmp_path):
    rows = synthetic_rows()
    stats = run_stats(rows, SKIP_S, PERIOD_S)
    old = "\n".join(report_lines(run_of(tmp_path), stats, "e-stop"))
    assert "not checked" in old and "not recorded" in old and "aborted (e-stop)" in old
    healthy = {**stats, "health": {**UNHEALTHY, "ok": True, "reasons": []}}
    verdict = report_lines(run_of(tmp_path), healthy, None)[-1]
    assert "healthy" in verdict and "NOT" not in verdict


@pytest.mark.slow
def test_report_plots_only_the_scored_part_and_breaks_lines_at_missing_ticks(tmp_path):
    rows = synthetic_rows(gap=(3.0, 3.4))
    stats = run_stats(rows, SKIP_S, PERIOD_S)
    figure = report_figure(rows, ["title"], stats, SKIP_S, PERIOD_S)
    try:
        for axes in figure.axes[:6]:
            for line in axes.lines:
                t = np.asarray(line.get_xdata(), dtype=float)
                y = np.asarray(line.get_ydata(), dtype=float)
                assert t[0] >= 1.0 + SKIP_S - 1e-9 and t[-1] <= 6.0  # no approach, no stop
                inside = (t > 3.0) & (t < 3.4)
                assert inside.sum() == 1 and np.isnan(y[inside]).all()  # the line breaks
                assert np.isfinite(y[~inside]).all()
        errors = np.concatenate([np.asarray(a.lines[0].get_ydata()) for a in figure.axes[3:6]])
        assert np.nanmax(np.abs(errors)) <= 1.0 + 1e-9  # the 50 mm approach error is out
    finally:
        plt.close(figure)


@pytest.mark.slow
def test_write_report_saves_a_png_and_a_vector_pdf(tmp_path):
    rows = synthetic_rows()
    stats = {**run_stats(rows, SKIP_S, PERIOD_S), "health": UNHEALTHY}
    paths = write_report(tmp_path, rows, run_of(tmp_path), stats, None, SKIP_S, PERIOD_S)
    png, pdf = (path.read_bytes() for path in paths)
    assert [p.name for p in paths] == ["report.png", "report.pdf"]
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and pdf[:5] == b"%PDF-"
    assert b"/Subtype /Image" not in pdf  # vector: lines and text, no embedded raster
    assert b"/FontFile2" in pdf  # TrueType fonts embedded: text stays text in print


@pytest.mark.slow
def test_a_run_that_ended_before_its_test_shows_the_whole_run(tmp_path):
    rows = [r for r in synthetic_rows() if r["phase"] == "approach"]
    stats = run_stats(rows, SKIP_S, PERIOD_S)
    figure = report_figure(rows, ["title"], stats, SKIP_S, PERIOD_S)
    try:
        assert "No scored part" in texts_of(figure)
        assert len(figure.axes[0].lines[0].get_xdata()) == len(rows)
    finally:
        plt.close(figure)


@pytest.mark.parametrize("period_s", [0.01, 0.02])
def test_break_gaps_inserts_one_nan_row_per_gap_and_nothing_else(period_s):
    rng = np.random.default_rng(1)
    steps = np.where(rng.random(300) < 0.05, 5 * period_s, period_s)
    times = np.cumsum(steps)
    values = rng.normal(size=(300, 3))
    t, v = break_gaps(times, values, period_s)
    gaps = int(np.sum(np.diff(times) > 1.5 * period_s))
    nan_rows = np.isnan(v).all(axis=1)
    assert nan_rows.sum() == gaps and len(t) == len(times) + gaps
    assert np.array_equal(t[~nan_rows], times) and np.array_equal(v[~nan_rows], values)
    assert np.all(np.diff(t) > 0)  # each break lies inside its gap
    assert np.all(np.diff(t[~nan_rows][np.diff(np.append(t, np.inf))[~nan_rows] > 0]) > 0)


def test_scored_mask_is_the_part_the_statistics_score():
    rows = synthetic_rows()
    times = np.array([r["t_s"] for r in rows])
    mask = scored_mask(times, [r["phase"] for r in rows], SKIP_S)
    goal, measured = (
        np.array([[r[f"{k}_{a}_m"] for a in "xyz"] for r in rows]) for k in ("goal", "measured")
    )
    assert error_stats(goal, measured, mask) == run_stats(rows, SKIP_S, PERIOD_S)["tracking"]
    assert times[mask][0] == pytest.approx(1.0 + SKIP_S, abs=PERIOD_S)


@pytest.mark.slow
def test_a_program_run_has_its_error_per_line_in_stats_and_report(tmp_path):
    """Rows of a G-code program: the per-line stats are the error's magnitude grouped by
    line (hand-computed on a made-up error), and the report draws one bar pair per line."""
    rows = synthetic_rows()
    timed = [r for r in rows if r["phase"] == "timed"]
    for k, row in enumerate(timed):  # lines 3 then 7; the error is (3, 4, 0) mm on line 7
        row["line"] = 3 if k < len(timed) // 2 else 7
        if row["line"] == 7:
            row["measured_x_m"] = row["goal_x_m"] - 0.003
            row["measured_y_m"] = row["goal_y_m"] - 0.004
            row["measured_z_m"] = row["goal_z_m"]
    stats = run_stats(rows, SKIP_S, PERIOD_S)
    per_line = stats["program"]["lines"]
    assert [e["line"] for e in per_line] == [3, 7]
    assert sum(e["samples"] for e in per_line) == len(timed)
    assert per_line[1]["rmse_m"] == pytest.approx(0.005) and per_line[1]["max_m"] == pytest.approx(
        0.005
    )
    run = run_of(tmp_path, "program", {"gcode": "G0 X0", "lines": 8, "segments": 2})
    figure = report_figure(rows, report_lines(run, stats, None), stats, SKIP_S, PERIOD_S)
    try:
        text = texts_of(figure)
        assert "G-code program: 8 lines" in text and "worst line 7" in text
        bars = [a for a in figure.axes if a.get_xlabel() == "program line"]
        assert len(bars) == 1 and len(bars[0].patches) == 2 * len(per_line)
    finally:
        plt.close(figure)
    assert "program" not in run_stats(synthetic_rows(), SKIP_S, PERIOD_S)


@pytest.mark.slow
def test_a_wrist_run_has_its_phi_in_stats_and_a_phi_row_in_the_report():
    rows = synthetic_rows()
    for row in rows:  # the wrist 0.1 rad behind a 0.5 rad sine in the timed part
        phi = 0.5 * math.sin(row["t_s"])
        row["phi_goal_rad"] = row["phi_commanded_rad"] = phi
        row["phi_measured_rad"] = phi - 0.1
    stats = run_stats(rows, SKIP_S, PERIOD_S)
    assert stats["wrist"]["mean_rad"] == pytest.approx(0.1)
    assert stats["wrist"]["rmse_rad"] == pytest.approx(0.1)
    figure = report_figure(rows, ["title"], stats, SKIP_S, PERIOD_S)
    plain = report_figure(
        synthetic_rows(), ["title"], run_stats(synthetic_rows(), SKIP_S, PERIOD_S), SKIP_S, PERIOD_S
    )
    try:
        assert len(figure.axes) == len(plain.axes) + 1  # one more row: phi
        phi_axis = figure.axes[-1]
        assert phi_axis.get_ylabel() == "wrist phi [deg]"
        goal = phi_axis.lines[0].get_ydata()
        assert np.nanmax(goal) == pytest.approx(math.degrees(0.5), abs=0.5)
        assert "phi RMSE 5.73 deg" in phi_axis.get_title()
    finally:
        plt.close(figure)
        plt.close(plain)
    assert "wrist" not in run_stats(synthetic_rows(), SKIP_S, PERIOD_S)

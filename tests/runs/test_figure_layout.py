"""The report and the comparison figures never print text over text: the verdict's lines,
the plot titles, the axis labels and the legends each get their own place, however many
reasons a run's verdict has or however many runs a comparison overlays.

Measured from the renderer (matplotlib's own bounding boxes, in display pixels): every
piece of the heading and the caption is clear of every axes' tight box (its title, labels,
tick labels, legend), the figure legend is clear of every axes, and the axes are clear of
each other."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import pytest
from matplotlib.transforms import Bbox

from app.runs import compare
from app.runs.recorder import run_stats
from app.runs.report import report_figure, report_lines
from app.runs.run import Run
from tests.support.saved_runs import (
    CONDITIONS,
    PERIOD_S,
    SINUSOID,
    SKIP_S,
    UNHEALTHY,
    save_run,
    synthetic_rows,
)

MANY_REASONS = [
    "a gap of 318 ms between ticks (over 20 ms)",
    "12 overruns (2.1 % of ticks, over 1 %)",
    "stale feedback for 84 ticks, the longest 600 ms (over 100 ms)",
    "the loop ran at 141 Hz, not its 50 Hz target (outside 45-55 Hz)",
    "lateness p99 12.5 ms (over 5 ms) while the servos were read at 8 ms a transaction",
    "the drone pose was late for 1.2 s in all (over 0.2 s) while the hold went on",
    "the bus had 3 timeouts and 2 checksum errors in the scored part of the run",
]


def _boxes(figure) -> tuple[list[tuple[str, Bbox]], list[tuple[str, Bbox]], list[Bbox]]:
    """(figure texts, figure legends, axes tight boxes) in display pixels, as drawn."""
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    texts = [(t.get_text(), t.get_window_extent(renderer)) for t in figure.texts if t.get_text()]
    legends = [("legend", legend.get_window_extent(renderer)) for legend in figure.legends]
    axes = [a.get_tightbbox(renderer) for a in figure.axes]
    return texts, legends, axes


def _clear(a: Bbox, b: Bbox, pad_px: float = 1.0) -> bool:
    """The boxes do not intersect (touching within ``pad_px`` counts as clear)."""
    return (
        a.x1 <= b.x0 + pad_px
        or b.x1 <= a.x0 + pad_px
        or a.y1 <= b.y0 + pad_px
        or b.y1 <= a.y0 + pad_px
    )


def assert_no_overlap(figure) -> None:
    texts, legends, axes = _boxes(figure)
    width, height = figure.bbox.width, figure.bbox.height
    for name, box in texts + legends:
        for index, axes_box in enumerate(axes):
            assert _clear(box, axes_box), f"{name!r} overlaps the plots of axes {index}"
        # inside the figure: nothing cut off at its edges
        assert box.x0 >= -1 and box.y0 >= -1, name
        assert box.x1 <= width + 1 and box.y1 <= height + 1, name
    pieces = texts + legends
    for i, (name, box) in enumerate(pieces):
        for other, other_box in pieces[i + 1 :]:
            assert _clear(box, other_box), f"{name!r} overlaps {other!r}"
    for i, box in enumerate(axes):
        for j in range(i + 1, len(axes)):
            assert _clear(box, axes[j]), f"axes {i} and {j} overlap (titles, labels, legends)"


def test_the_overlap_check_finds_a_heading_printed_over_a_title():
    """The check itself can fail: a text placed on an axes' title is caught."""
    figure, axes = plt.subplots(1, 2, figsize=(8, 3))
    try:
        axes[0].set_title("x: RMSE 1 mm")
        figure.tight_layout()
        figure.canvas.draw()
        title = axes[0].title.get_window_extent(figure.canvas.get_renderer())
        x, y = figure.transFigure.inverted().transform((title.x0, title.y0))
        figure.text(x, y, "verdict: NOT HEALTHY, the figures do not stand")
        with pytest.raises(AssertionError, match="overlaps"):
            assert_no_overlap(figure)
    finally:
        plt.close(figure)


def _run(tmp_path: Path) -> Run:
    return Run("20260101-120000-abcd", "sinusoid", SINUSOID, CONDITIONS, tmp_path)


@pytest.mark.parametrize("reasons", [1, 3, len(MANY_REASONS)])
def test_a_report_with_many_verdict_reasons_has_nothing_over_anything(tmp_path, reasons):
    rows = synthetic_rows()
    health = {**UNHEALTHY, "reasons": MANY_REASONS[:reasons]}
    stats = {**run_stats(rows, SKIP_S, PERIOD_S), "health": health}
    lines = report_lines(_run(tmp_path), stats, "e-stop pressed by the operator")
    figure = report_figure(rows, lines, stats, SKIP_S, PERIOD_S)
    try:
        shown = " ".join(t.get_text() for t in figure.texts)
        for reason in MANY_REASONS[:reasons]:  # every reason is there, in full
            assert reason.split()[-1] in shown
        assert_no_overlap(figure)
    finally:
        plt.close(figure)


def test_a_program_report_with_a_wrist_and_many_reasons_has_nothing_over_anything(tmp_path):
    rows = synthetic_rows()
    for index, row in enumerate(rows):
        row["line"] = 10 + (index // 50)
        row["phi_goal_rad"] = 0.3
        row["phi_measured_rad"] = 0.29
    health = {**UNHEALTHY, "reasons": MANY_REASONS}
    stats = {**run_stats(rows, SKIP_S, PERIOD_S), "health": health}
    lines = report_lines(_run(tmp_path), stats, None)
    figure = report_figure(rows, lines, stats, SKIP_S, PERIOD_S)
    try:
        assert len(figure.axes) >= 7  # the per-line row and the wrist's row are there
        assert_no_overlap(figure)
    finally:
        plt.close(figure)


@pytest.mark.parametrize("count", [2, compare.MAX_RUNS])
def test_a_comparison_of_many_runs_has_its_legend_clear_of_the_plots(tmp_path, count):
    saved = [
        save_run(tmp_path, f"20260101-1200{i:02d}-abcd", synthetic_rows(), UNHEALTHY)
        for i in range(count)
    ]
    records = [run.as_dict() for run in saved]
    figure = compare.figure(records, [run.folder for run in saved], SKIP_S)
    try:
        assert len(figure.legends) == 1
        assert len(figure.legends[0].get_texts()) == count
        assert_no_overlap(figure)
    finally:
        plt.close(figure)

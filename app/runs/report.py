"""A run's report figure in the thesis's layout (Fig. 6.2-6.4), fit to publish.

Per axis, goal and measured position on top and the error underneath, over the scored part
of the run only (the approach, the first ``runs.stats_skip_s`` of the test and the stop are
left out, as in the statistics). Lines break where ticks are missing. Above the plots, in
words and units (app/runs/describe.py): the test and its parameters, the loop's figures and
the health verdict. Saved as report.png (screen) and report.pdf (vector, for print).
"""

from __future__ import annotations

import math
import textwrap
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")  # files only: no display on a server

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from app.runs import describe  # noqa: E402
from app.runs.stats import AXES  # noqa: E402

# pyplot's figure list and rc_context's global rcParams are not thread-safe: a report
# drawn in a run's writer thread and a comparison drawn for a request take turns.
DRAWING = threading.Lock()

if TYPE_CHECKING:
    from app.runs.run import Run

SCORED_PHASES = ("timed", "hold")
GAP_PERIODS = 1.5  # a step between ticks over this many loop periods is a gap
FILES = ("report.png", "report.pdf")
STYLE = {  # print: sizes legible at a column's width, text kept as text in the PDF
    "font.size": 9,
    "axes.titlesize": 9,
    "axes.labelsize": 9,
    "legend.fontsize": 8,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "pdf.fonttype": 42,
    "axes.grid": True,
    "grid.alpha": 0.3,
}
GOAL = {"color": "black", "linestyle": (0, (4, 2)), "linewidth": 1.0}  # dashed: reads in grey
MEASURED = {"color": "tab:blue", "linewidth": 1.1}
ERROR = {"color": "tab:red", "linewidth": 0.9}
BAD = "#b00020"


def scored_mask(times_s: np.ndarray, phases: Sequence[str], skip_s: float) -> np.ndarray:
    """The samples the statistics score (N,) bool: phase "timed" or "hold", from ``skip_s``
    [s] after the first such sample on (the rule of recorder.run_stats)."""
    times = np.asarray(times_s, dtype=np.float64)
    active = np.array([p in SCORED_PHASES for p in phases], dtype=bool)
    if active.any():
        active &= times >= float(times[active][0]) + skip_s
    return active


def break_gaps(
    times_s: np.ndarray, values: np.ndarray, period_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """(times (M,), values (M, ...)) with a NaN row inserted in every gap between samples
    longer than ``GAP_PERIODS`` loop periods, so a plotted line breaks there instead of
    drawing a straight line across the missing ticks. ``times_s`` (N,) increasing [s]."""
    times = np.asarray(times_s, dtype=np.float64)
    data = np.asarray(values, dtype=np.float64)
    gaps = np.flatnonzero(np.diff(times) > GAP_PERIODS * period_s)
    if gaps.size == 0:
        return times, data
    middle = (times[gaps] + times[gaps + 1]) / 2
    return np.insert(times, gaps + 1, middle), np.insert(data, gaps + 1, np.nan, axis=0)


def columns(rows: list[dict[str, Any]], prefix: str) -> np.ndarray:
    """(N, 3) [m] of the log columns ``{prefix}_{x,y,z}_m``; None becomes NaN."""
    return np.array(
        [
            [np.nan if r.get(f"{prefix}_{a}_m") is None else r[f"{prefix}_{a}_m"] for a in AXES]
            for r in rows
        ],
        dtype=np.float64,
    ).reshape(len(rows), 3)


def reference_and_measured(rows: list[dict[str, Any]], world: bool) -> tuple[np.ndarray, ...]:
    """(reference, measured), each (N, 3) [m]: world frame for hold runs, else goal and FK."""
    names = ("world_goal", "world_measured") if world else ("goal", "measured")
    return tuple(columns(rows, name) for name in names)


def report_lines(
    run: Run, stats: dict[str, Any], abort_reason: str | None, state: str | None = None
) -> list[str]:
    """The figure's heading: run and outcome, the test in words, the loop, the verdict.
    ``state`` overrides the outcome read from ``abort_reason`` (e.g. "interrupted")."""
    state = state or ("aborted" if abort_reason else "done")
    return [
        f"Run {run.run_id}: {run.kind}, {describe.outcome(state, abort_reason)}",
        describe.describe(run.kind, run.params, run.conditions),
        describe.loop_figures(stats, run.conditions),
        describe.verdict(stats),
    ]


def _caption(times: np.ndarray, scored: np.ndarray, skip_s: float, gaps: int) -> str:
    total = f"{describe.number(float(times[-1]))} s" if times.size else "0 s"
    if not scored.any():
        return f"No scored part (the run ended before its test): the whole run ({total}) is shown."
    first, last = (describe.number(float(t)) for t in times[scored][[0, -1]])
    plural = "s" if gaps > 1 else ""
    breaks = f"; lines break at {gaps} gap{plural} in the ticks" if gaps else ""
    return (
        f"Scored part only: t = {first} to {last} s of {total} (approach, first "
        f"{describe.number(skip_s)} s of the test and stop left out){breaks}."
    )


def report_figure(
    rows: list[dict[str, Any]],
    lines: list[str],
    stats: dict[str, Any],
    skip_s: float,
    period_s: float,
) -> Figure:
    """The report figure of a run's log ``rows`` (see logs.COLUMNS) under the heading
    ``lines`` (see :func:`report_lines`); the caller saves and closes it."""
    times = np.array([r["t_s"] for r in rows], dtype=np.float64)
    scored = scored_mask(times, [r["phase"] for r in rows], skip_s)
    shown = scored if scored.any() else np.ones_like(scored)
    world = "world" in stats
    reference, measured = (v[shown] for v in reference_and_measured(rows, world))
    t, both = break_gaps(times[shown], np.hstack([reference, measured]), period_s)
    gaps = int(t.size - shown.sum())
    axis_stats = stats.get("world", stats.get("tracking")) or {}
    per_line = (stats.get("program") or {}).get("lines") or []
    phi = _phi_columns(rows)[shown]  # (M, 2) [rad]: the wrist's goal and reading
    wrist = bool(np.isfinite(phi[:, 0]).any())
    extras = (["lines"] if per_line else []) + (["wrist"] if wrist else [])
    with plt.rc_context(STYLE):
        heading = heading_pieces(lines)
        top_in, bottom_in = heading_height_in(heading), CAPTION_IN
        height_in = PLOTS_IN + 2.4 * len(extras) + top_in + bottom_in
        if extras:  # a G-code program: a row of the error per program line; a wrist: phi
            figure = plt.figure(figsize=(11, height_in))
            ratios = [2, 1, *(1.2 for _ in extras)]
            grid = figure.add_gridspec(2 + len(extras), 3, height_ratios=ratios)
            axes = np.empty((2, 3), dtype=object)
            for i in range(3):
                axes[0, i] = figure.add_subplot(grid[0, i], sharex=axes[0, 0] if i else None)
                axes[1, i] = figure.add_subplot(grid[1, i], sharex=axes[0, 0])
            for k, extra in enumerate(extras):
                if extra == "lines":
                    _per_line(figure.add_subplot(grid[2 + k, :]), per_line)
                else:
                    row = figure.add_subplot(grid[2 + k, :], sharex=axes[0, 0])
                    _wrist(row, *break_gaps(times[shown], phi, period_s), stats)
        else:
            figure, axes = plt.subplots(
                2, 3, figsize=(11, height_in), sharex=True, gridspec_kw={"height_ratios": [2, 1]}
            )
        for i, name in enumerate(AXES):
            top, bottom = axes[0, i], axes[1, i]
            top.plot(t, both[:, i] * 1e3, label="goal", **GOAL)
            top.plot(t, both[:, 3 + i] * 1e3, label="measured (FK)", **MEASURED)
            frame = "world " if world else ""
            top.set_ylabel(f"{frame}{name} [mm]")
            bottom.plot(t, (both[:, i] - both[:, 3 + i]) * 1e3, **ERROR)
            bottom.set_ylabel(f"{name} error [mm]")
            bottom.set_xlabel("run time [s]")
            s = axis_stats.get(name, {})
            top.set_title(  # two lines: one would run into the next column's title
                f"{name}: RMSE {describe.mm(s.get('rmse_m'))}\n"
                f"mean {describe.mm(s.get('mean_m'))}, max |e| {describe.mm(s.get('max_abs_m'))}"
            )
        axes[0, 0].legend(loc="upper right")
        _heading(figure, heading)
        caption = _caption(times, scored, skip_s, gaps)
        figure.text(0.01, 0.1 / height_in, caption, fontsize=8, va="bottom")
        # the plots fill what the heading and the caption leave, never under them
        rect = (0, bottom_in / height_in, 1, 1 - top_in / height_in)
        figure.tight_layout(rect=rect)
    return figure


def _phi_columns(rows: list[dict[str, Any]]) -> np.ndarray:
    """(N, 2) [rad]: the wrist's goal and measured phi (log columns; None becomes NaN)."""
    names = ("phi_goal_rad", "phi_measured_rad")
    return np.array(
        [[np.nan if r.get(n) is None else r[n] for n in names] for r in rows], dtype=np.float64
    ).reshape(len(rows), 2)


def _wrist(axis: Any, t: np.ndarray, phi: np.ndarray, stats: dict[str, Any]) -> None:
    """The wrist's goal and measured phi [deg] against run time, its error (and, in a hold,
    the world heading's) in the title."""
    axis.plot(t, np.degrees(phi[:, 0]), label="goal", **GOAL)
    axis.plot(t, np.degrees(phi[:, 1]), label="measured", **MEASURED)
    axis.set_ylabel("wrist phi [deg]")
    axis.set_xlabel("run time [s]")
    title = "wrist phi"
    for label, key in (("phi", "wrist"), ("world heading", "heading")):
        s = stats.get(key) if key == "wrist" else (stats.get("world") or {}).get("heading")
        if s and s.get("samples"):
            title += (
                f"; {label} RMSE {describe.number(math.degrees(s['rmse_rad']))} deg, max |e| "
                f"{describe.number(math.degrees(s['max_abs_rad']))} deg"
            )
    axis.set_title(title)
    axis.legend(loc="upper right")


def _per_line(axis: Any, per_line: list[dict[str, Any]]) -> None:
    """Bars of the RMSE and the largest |error| per program line [mm], the worst named."""
    labels = [str(e["line"]) for e in per_line]
    x = np.arange(len(per_line))
    rmse = np.array([e["rmse_m"] for e in per_line], dtype=float) * 1e3
    worst = np.array([e["max_m"] for e in per_line], dtype=float) * 1e3
    axis.bar(x - 0.2, rmse, 0.4, label="RMSE |e|", color="tab:blue")
    axis.bar(x + 0.2, worst, 0.4, label="max |e|", color="tab:red")
    step = max(1, len(labels) // 40)  # at most ~40 labels legible
    axis.set_xticks(x[::step], labels[::step])
    axis.set_xlabel("program line")
    axis.set_ylabel("error [mm]")
    top = int(np.nanargmax(worst)) if np.isfinite(worst).any() else None
    title = "tracking error per program line (timed part, every sample)"
    if top is not None:
        title += (
            f"; worst line {per_line[top]['line']}: RMSE {describe.number(rmse[top])} mm, "
            f"max {describe.number(worst[top])} mm"
        )
    axis.set_title(title)
    axis.legend(loc="upper right")


def wrap(line: str, width: int) -> list[str]:
    """``line`` in pieces of at most ``width`` characters, broken after "; " where it can
    be (between the clauses of describe's sentences), else at spaces."""
    pieces: list[str] = []
    for clause in line.split("; "):
        if pieces and len(pieces[-1]) + 2 + len(clause) <= width:
            pieces[-1] += "; " + clause
        else:
            if pieces:
                pieces[-1] += ";"
            pieces.extend(textwrap.wrap(clause, width) or [""])
    return pieces


HEADING_WIDTH = 130  # characters a heading line is wrapped at (fits 11 in at 9 pt)
TITLE_PT, LINE_PT, LEADING = 11, 9, 1.45  # heading font sizes [pt]; line height / size
PLOTS_IN = 6.6  # the six plots' height [in]; the heading and the caption come on top
CAPTION_IN = 0.35  # the caption's strip at the bottom [in]


def heading_pieces(lines: list[str]) -> list[tuple[str, bool, bool]]:
    """The heading as printed, one entry per printed line: (text, is the title, is an
    unhealthy verdict's line); every line of ``lines`` wrapped at HEADING_WIDTH."""
    pieces = []
    for index, line in enumerate(lines):
        healthy = not line.startswith("verdict: NOT")
        pieces += [(part, index == 0, not healthy) for part in wrap(line, HEADING_WIDTH)]
    return pieces


def heading_height_in(pieces: list[tuple[str, bool, bool]]) -> float:
    """The height [in] the heading's printed lines take, with a margin above and below."""
    points = sum((TITLE_PT if title else LINE_PT) * LEADING for _, title, _ in pieces)
    return points / 72.0 + 0.2


def _heading(figure: Figure, pieces: list[tuple[str, bool, bool]]) -> None:
    """The heading's lines from the top of ``figure`` down, each at its own height, so
    that however many a verdict has they take the room heading_height_in gave them."""
    height_in = figure.get_figheight()
    y_in = 0.1
    for text, title, bad in pieces:
        figure.text(
            0.01,
            1 - y_in / height_in,
            text,
            va="top",
            fontsize=TITLE_PT if title else LINE_PT,
            fontweight="bold" if title or bad else "normal",
            color=BAD if bad else "black",
        )
        y_in += (TITLE_PT if title else LINE_PT) * LEADING / 72.0


def write_report(
    folder: Path,
    rows: list[dict[str, Any]],
    run: Run,
    stats: dict[str, Any],
    abort_reason: str | None,
    skip_s: float,
    period_s: float,
    state: str | None = None,
) -> list[Path]:
    """Save report.png and report.pdf (vector) of ``rows`` in ``folder``; their paths.

    ``stats`` as computed by recorder.run_stats (with ``health`` when recorded),
    ``skip_s`` [s] the stats' skip at the test's start, ``period_s`` [s] the loop period,
    ``state`` the outcome when it is not read from ``abort_reason`` ("interrupted")."""
    lines = report_lines(run, stats, abort_reason, state)
    paths = [folder / name for name in FILES]
    with DRAWING:
        figure = report_figure(rows, lines, stats, skip_s, period_s)
        try:
            with plt.rc_context(STYLE):  # the PDF's font type is read when saving
                for path in paths:
                    figure.savefig(path, dpi=110)
        finally:
            plt.close(figure)
    return paths

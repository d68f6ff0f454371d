"""Two or more runs side by side: their statistics as one table, their errors overlaid.

The same for the API (GET /api/runs/compare, /api/runs/compare.png), the dashboard and
``deltadash runs compare``. Runs come as their saved records (run.json / RunOut dicts, SI
units); the table gives display units (mm, %, Hz, ms) with the unit in its own field. The
figure plots each run's error over its scored part (the part the statistics score), time
counted from the start of that part so the runs line up.
"""

from __future__ import annotations

import textwrap
from io import BytesIO
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from app.runs import describe  # noqa: E402
from app.runs.report import DRAWING, STYLE, break_gaps, reference_and_measured, scored_mask  # noqa: E402
from app.runs.stats import AXES  # noqa: E402

MIN_RUNS, MAX_RUNS = 2, 8


class CompareError(ValueError):
    """The runs asked for cannot be compared; the message says which field and why."""


def parse_ids(ids: str | list[str]) -> list[str]:
    """Run ids from "a,b,c" or a list, in order, without repeats; CompareError unless
    there are MIN_RUNS to MAX_RUNS of them."""
    raw = ids.split(",") if isinstance(ids, str) else list(ids)
    unique = list(dict.fromkeys(i.strip() for i in raw if i.strip()))
    if len(unique) < MIN_RUNS:
        raise CompareError(
            f"ids: give {MIN_RUNS} or more different run ids, comma-separated (got {len(unique)})"
        )
    if len(unique) > MAX_RUNS:
        raise CompareError(f"ids: at most {MAX_RUNS} runs at once (got {len(unique)})")
    return unique


def _scored_stats(run: dict[str, Any]) -> dict[str, Any]:
    stats = run.get("stats") or {}
    return stats.get("world") or stats.get("tracking") or {}


def _axis_rows(run_stats: list[dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for key, label, unit, scale in (
        ("rmse_m", "RMSE", "mm", 1e3),
        ("max_abs_m", "max |e|", "mm", 1e3),
        ("mean_m", "mean", "mm", 1e3),
        ("share_under_1mm", "< 1 mm", "%", 100.0),
    ):
        for axis in AXES:
            values = [_scaled((s.get(axis) or {}).get(key), scale) for s in run_stats]
            rows.append({"label": f"{label} {axis}", "unit": unit, "values": values})
    return rows


def _scaled(value: Any, scale: float) -> float | None:
    real = isinstance(value, int | float) and not isinstance(value, bool)
    return float(value) * scale if real and np.isfinite(value) else None


def _health_value(run: dict[str, Any], *path: str) -> float | None:
    value: Any = (run.get("stats") or {}).get("health") or {}
    for key in path:
        value = value.get(key) if isinstance(value, dict) else None
    return _scaled(value, 1.0)


def _verdict(run: dict[str, Any]) -> str:
    health = (run.get("stats") or {}).get("health")
    if not isinstance(health, dict) or not isinstance(health.get("ok"), bool):
        return "not checked"
    if health["ok"]:
        return "healthy"
    return "NOT HEALTHY: " + "; ".join(str(r) for r in health.get("reasons") or [])


def table(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The comparison table: one row per figure, {"label", "unit", "values"} with one value
    per run (a number in ``unit``, a text, or None where the run has none)."""
    scored = [_scored_stats(r) for r in runs]

    def row(label: str, unit: str, values: list[Any]) -> dict[str, Any]:
        return {"label": label, "unit": unit, "values": values}

    return [
        row("test", "", [describe.describe(r["kind"], r["params"], r["conditions"]) for r in runs]),
        row("state", "", [describe.outcome(r["state"], r.get("reason")) for r in runs]),
        row("verdict", "", [_verdict(r) for r in runs]),
        row("loop rate", "Hz", [_health_value(r, "rate_hz") for r in runs]),
        row("lateness p99", "ms", [_health_value(r, "lateness_ms", "p99") for r in runs]),
        row("longest gap", "ms", [_health_value(r, "longest_gap_ms") for r in runs]),
        row("stale feedback", "ticks", [_health_value(r, "stale_ticks") for r in runs]),
        row("scored samples", "", [_scaled(s.get("samples"), 1.0) for s in scored]),
        *_axis_rows(scored),
    ]


def format_table(runs: list[dict[str, Any]], width: int = 24) -> str:
    """The table as text for a terminal: a column per run; a text row with a value longer
    than ``width`` (the test, a verdict's reasons) is written out under the table."""
    header = ["", *(r["run_id"] for r in runs)]
    lines, notes = [header], []
    for entry in table(runs):
        values = entry["values"]
        if any(isinstance(v, str) and len(v) > width for v in values):
            notes += [
                f"{r['run_id']} {entry['label']}: {v}" for r, v in zip(runs, values, strict=True)
            ]
            continue
        label = f"{entry['label']} [{entry['unit']}]" if entry["unit"] else entry["label"]
        lines.append([label, *(v if isinstance(v, str) else describe.number(v) for v in values)])
    widths = [max(len(line[i]) for line in lines) for i in range(len(header))]
    text = [
        "  ".join(
            c.ljust(w) if i == 0 else c.rjust(w)
            for i, (c, w) in enumerate(zip(line, widths, strict=True))
        ).rstrip()
        for line in lines
    ]
    return "\n".join(text + ([""] + notes if notes else []))


def scored_errors(
    rows: list[dict[str, Any]], world: bool, skip_s: float, period_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """(t (M,) [s] from the start of the scored part, error (M, 3) [m] = reference -
    measured) over the scored part of a run's log ``rows``, NaN rows where ticks are
    missing (report.break_gaps); empty when nothing was scored."""
    if not rows:
        return np.empty(0), np.empty((0, 3))
    times = np.array([r["t_s"] for r in rows], dtype=np.float64)
    mask = scored_mask(times, [r["phase"] for r in rows], skip_s)
    if not mask.any():
        return np.empty(0), np.empty((0, 3))
    reference, measured = reference_and_measured(rows, world)
    t, error = break_gaps(times[mask], (reference - measured)[mask], period_s)
    return t - t[0], error


def _line(index: int) -> dict[str, Any]:
    """Colour and dash per run: the overlay still reads in grey print."""
    dashes = ["solid", (0, (5, 2)), (0, (1, 1.5)), (0, (6, 2, 1, 2))]
    return {"color": f"C{index}", "linestyle": dashes[index % len(dashes)], "linewidth": 1.0}


def load_rows(folder: Path) -> list[dict[str, Any]] | None:
    """A run's logged ticks from its log.mcap, or None when there is no readable log."""
    from app.runs.logs import read_messages

    try:
        return read_messages(folder / "log.mcap")
    except (OSError, ValueError):
        return None


def figure(runs: list[dict[str, Any]], folders: list[Path], skip_s: float) -> Figure:
    """Per axis, each run's error over its scored part, overlaid; the caller closes it."""
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, 3, figsize=(11, 3.8), sharex=True)
        missing = []
        for index, (run, folder) in enumerate(zip(runs, folders, strict=True)):
            rows = load_rows(folder)
            period_s = 1.0 / float((run.get("conditions") or {}).get("loop_rate_hz") or 50.0)
            world = "world" in (run.get("stats") or {})
            t, error = scored_errors(rows or [], world, skip_s, period_s)
            if not t.size:
                missing.append(run["run_id"])
                continue
            ff = describe.on_off((run.get("params") or {}).get("feedforward"))
            label = f"{run['run_id']} ({run['kind']}, feed-forward {ff})"
            for i, axes_i in enumerate(axes):
                axes_i.plot(t, error[:, i] * 1e3, label=label, **_line(index))
        for axis, axes_i in zip(AXES, axes, strict=True):
            axes_i.set_title(f"{axis} error [mm]")
            axes_i.set_xlabel("time in the scored part [s]")
        axes[0].set_ylabel("reference − measured [mm]")
        handles, labels = axes[0].get_legend_handles_labels()
        rows_of_legend = (len(handles) + 1) // 2
        fig.set_figheight(3.8 + 0.2 * rows_of_legend)  # the plots keep their height
        note = "Scored part of each run (as in its statistics); lines break at missing ticks."
        if missing:
            note += " Nothing scored or no log: " + ", ".join(missing) + "."
        fig.text(0.01, 0.01, "\n".join(textwrap.wrap(note, 150)), fontsize=8, va="bottom")
        top = 1.0
        if handles:
            legend = fig.legend(
                handles,
                labels,
                loc="upper center",
                bbox_to_anchor=(0.5, 1.0),
                ncol=2,
                frameon=False,
            )
            top = _bottom_of(fig, legend) - 0.01
        # the plots (titles included) fill what is left under the legend, over the note
        fig.tight_layout(rect=(0, _top_of(fig, fig.texts[-1]) + 0.01, 1, top))
    return fig


def _bottom_of(fig: Figure, artist: Any) -> float:
    """Where ``artist``'s drawn box starts from the bottom, as a fraction of the figure."""
    fig.canvas.draw()
    box = artist.get_window_extent(fig.canvas.get_renderer())
    return float(fig.transFigure.inverted().transform((box.x0, box.y0))[1])


def _top_of(fig: Figure, artist: Any) -> float:
    """Where ``artist``'s drawn box ends at the top, as a fraction of the figure."""
    fig.canvas.draw()
    box = artist.get_window_extent(fig.canvas.get_renderer())
    return float(fig.transFigure.inverted().transform((box.x1, box.y1))[1])


def png(runs: list[dict[str, Any]], folders: list[Path], skip_s: float) -> bytes:
    """:func:`figure` as PNG bytes."""
    buffer = BytesIO()
    with DRAWING:
        fig = figure(runs, folders, skip_s)
        try:
            fig.savefig(buffer, format="png", dpi=100)
        finally:
            plt.close(fig)
    return buffer.getvalue()

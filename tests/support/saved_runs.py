"""Runs made up on disk (run.json and log.mcap, as a finished run leaves them), for tests of
what reads runs (the report, compare, the runs list) without driving a robot for seconds."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from app.runs.logs import COLUMNS, RunLog
from app.runs.recorder import run_stats
from app.runs.run import Run

PERIOD_S = 0.02
SKIP_S = 0.5
SINUSOID = {
    "amplitude_m": [0.05, 0.05, 0.08],
    "frequency_hz": [1.0, 1.0, 2.0],
    "phase_rad": [0.0, math.pi / 2, 0.0],
    "offset_m": [0.0, 0.0, -0.24],
    "duration_s": 10.0,
    "feedforward": True,
}
CONDITIONS = {"loop_rate_hz": 1 / PERIOD_S, "feedforward_lead_s": 0.02, "backend": "made up"}
UNHEALTHY = {
    "ok": False,
    "reasons": ["a gap of 318 ms between ticks (over 20 ms)"],
    "rate_hz": 141.2,
    "lateness_ms": {"p50": 0.4, "p99": 12.5, "worst": 318.0},
    "overruns": 12,
    "overrun_share": 0.021,
    "longest_gap_ms": 318.0,
    "stale_ticks": 84,
    "longest_stale_ms": 600.0,
    "thresholds": {"overrun_share": 0.01, "gap_ms": 20.0},
}
HEALTHY = {
    **UNHEALTHY,
    "ok": True,
    "reasons": [],
    "rate_hz": 50.0,
    "lateness_ms": {"p50": 0.2, "p99": 1.1, "worst": 3.0},
    "overruns": 0,
    "overrun_share": 0.0,
    "longest_gap_ms": 21.0,
    "stale_ticks": 0,
    "longest_stale_ms": 0.0,
}


def synthetic_rows(
    gap: tuple[float, float] = (3.0, 3.4), error_m: float = 0.001
) -> list[dict[str, Any]]:
    """Log rows (every logs.COLUMNS key) of a made-up run: approach 0-1 s, timed 1-6 s with
    the ticks inside ``gap`` missing, stop 6-7 s. The error (goal - measured) is
    ``error_m`` cos(3 t) on every axis in the timed part and 50 mm outside it."""
    times = np.arange(0.0, 7.0, PERIOD_S)
    times = times[(times < gap[0]) | (times > gap[1])]
    rows = []
    for t in times:
        phase = "approach" if t < 1.0 else "timed" if t <= 6.0 else "stop"
        error = 0.05 if phase != "timed" else error_m * math.cos(3 * t)
        row: dict[str, Any] = dict.fromkeys(COLUMNS)
        row.update({"t_s": float(t), "phase": phase, "mode": "test", "faults": ""})
        for axis, goal in zip("xyz", (0.05 * math.sin(t), 0.0, -0.24), strict=True):
            row[f"goal_{axis}_m"] = goal
            row[f"measured_{axis}_m"] = goal - error
        rows.append(row)
    return rows


def save_run(
    folder: Path,
    run_id: str,
    rows: list[dict[str, Any]],
    health: dict[str, Any] | None = None,
    kind: str = "sinusoid",
    params: dict[str, Any] | None = None,
) -> Run:
    """A finished run in ``folder``/``run_id``: log.mcap and log.csv of ``rows``, run.json
    with the stats the recorder computes (plus ``health`` when given)."""
    run = Run(run_id, kind, params or SINUSOID, CONDITIONS, folder / run_id)
    log = RunLog(run.folder, {"run_id": run_id})
    for row in rows:
        log.write(row)
    log.close()
    stats = run_stats(rows, SKIP_S, PERIOD_S)
    if health is not None:
        stats["health"] = health
    run.finish(stats, None, len(rows))
    run.save()
    return run

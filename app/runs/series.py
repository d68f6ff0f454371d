"""A run's recorded signals, decimated, for replay in the page's plots and its
interactive report (GET /api/runs/{run_id}/series).

The values are the log's own (log.mcap, the same ticks as log.csv), every ``stride``-th
tick from the first, so a replayed point is a recorded one, never an average. Units are
SI as in the log (m, rad, s); the page converts to mm and deg. Columns the run never
filled (no world frame outside a hold, no wrist) are left out.
"""

from __future__ import annotations

import math
from typing import Any

from app.runs.stats import AXES

DEFAULT_POINTS = 3000  # a 5-minute window at 50 Hz is 15000 ticks: 1 in 5 of them
MAX_POINTS = 20000  # the most samples one answer carries (per signal)

# the log's numeric columns replayed, in the page's order (logs.COLUMNS names)
SIGNALS = (
    *(f"goal_{a}_m" for a in AXES),
    *(f"measured_{a}_m" for a in AXES),
    *(f"commanded_q{i}_rad" for i in (1, 2, 3)),
    *(f"measured_q{i}_rad" for i in (1, 2, 3)),
    *(f"external_{a}_m" for a in AXES),
    *(f"world_goal_{a}_m" for a in AXES),
    *(f"world_measured_{a}_m" for a in AXES),
    "phi_goal_rad",
    "phi_measured_rad",
    "lateness_ms",
    *(f"contact_force_{a}_n" for a in AXES),
)


class SeriesError(ValueError):
    """The series cannot be given; the message names the field and why."""


def _number(value: Any) -> float | None:
    real = isinstance(value, int | float) and not isinstance(value, bool)
    return float(value) if real and math.isfinite(value) else None


def stride_for(samples: int, max_points: int) -> int:
    """Every how many ticks one is kept so that at most ``max_points`` remain (>= 1)."""
    if max_points < 1:
        raise SeriesError(f"max_points: must be 1 or more (got {max_points})")
    return max(1, math.ceil(samples / max_points))


def series(rows: list[dict[str, Any]], max_points: int = DEFAULT_POINTS) -> dict[str, Any]:
    """The recorded signals of a run's log ``rows`` (logs.COLUMNS dicts), decimated.

    Returns {"samples": N ticks in the log, "stride": k, "t_s": [M] run time [s],
    "phase": [M], "signals": {column: [M] value or None}} with M = ceil(N / k) <= max_points;
    ``signals`` also has ``error_{x,y,z}_m`` = goal - measured [m] and, in a hold,
    ``world_error_{x,y,z}_m`` (the report's errors). SeriesError for max_points < 1."""
    stride = stride_for(len(rows), max_points)
    kept = rows[::stride]
    signals: dict[str, list[float | None]] = {}
    for name in SIGNALS:
        values = [_number(r.get(name)) for r in kept]
        if any(v is not None for v in values):
            signals[name] = values
    for prefix in ("", "world_"):
        for a in AXES:
            goal, measured = (
                signals.get(f"{prefix}goal_{a}_m"),
                signals.get(f"{prefix}measured_{a}_m"),
            )
            if goal is None or measured is None:
                continue
            signals[f"{prefix}error_{a}_m"] = [
                None if g is None or m is None else g - m
                for g, m in zip(goal, measured, strict=True)
            ]
    return {
        "samples": len(rows),
        "stride": stride,
        "t_s": [float(r["t_s"]) for r in kept],
        "phase": [str(r.get("phase") or "") for r in kept],
        "signals": signals,
    }

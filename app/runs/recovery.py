"""Runs a crash left behind: a run.json still saying ``running`` whose writer is gone.

The run manager finds them when it starts (``RunManager`` loads the runs folder) and
finishes them here from what was logged: the state becomes ``interrupted`` with the
reason, the stats and the report are computed from the logged ticks, and the MCAP log is
made a complete file with a summary (the file as the crash left it is kept beside it as
``log.cut.mcap``). A run whose log is still locked by a live process (a second server or
a headless ``deltadash run`` on the same folder) is left alone.
"""

from __future__ import annotations

import logging
from typing import Any

from app.runs.health import assess
from app.runs.logs import finish_cut_log, is_being_written, read_csv_rows, read_messages
from app.runs.recorder import run_stats
from app.runs.report import write_report
from app.runs.run import Run

log = logging.getLogger(__name__)

CUT_LOG = "log.cut.mcap"  # the MCAP file as a crash left it, kept when it is finished


def abandoned(run: Run) -> bool:
    """A run recorded as running whose log no live process writes."""
    return run.state == "running" and not is_being_written(run.folder / "log.mcap")


def logged_rows(run: Run) -> list[dict[str, Any]]:
    """The ticks a run logged: from its MCAP log (the kept original if there is one), else
    from its CSV log; whole ticks only, up to where a crash cut the file."""
    for name in (CUT_LOG, "log.mcap"):
        if (run.folder / name).exists():
            rows = read_messages(run.folder / name)
            if rows:
                return rows
    csv_path = run.folder / "log.csv"
    return read_csv_rows(csv_path) if csv_path.exists() else []


def recover(run: Run, skip_s: float, period_s: float) -> list[dict[str, Any]]:
    """Finish an abandoned run from its logs and save its record (see the module's text).

    ``skip_s``: start of the scored part after the test begins [s] (``runs.stats_skip_s``);
    ``period_s``: the loop period the run ran at [s]. Raises OSError if the record cannot
    be saved; a log that cannot be read or finished only leaves the stats out and says so.
    Returns the logged rows the stats came from (empty without stats), for
    :func:`draw_report`.
    """
    mcap = run.folder / "log.mcap"
    last_written = max(
        (p.stat().st_mtime for p in (mcap, run.folder / "log.csv") if p.exists()),
        default=run.started_at,
    )
    notes: list[str] = []
    rows: list[dict[str, Any]] = []
    try:
        rows = logged_rows(run)
        if mcap.exists() or (run.folder / CUT_LOG).exists():
            finish_cut_log(mcap, run.folder / CUT_LOG)
        ros2 = run.folder / "log.ros2.mcap"
        if ros2.exists():  # the run as ROS 2 messages (app/runs/ros2_log.py)
            finish_cut_log(ros2, run.folder / "log.ros2.cut.mcap")
    except Exception as exc:  # noqa: BLE001 - a damaged log must not stop the server
        log.warning("run %s: its logs could not be recovered: %s", run.run_id, exc)
        notes.append(f"its logs could not be read whole ({exc})")
    run.samples = len(rows)
    run.stats = {}
    if rows:
        try:
            run.stats = run_stats(rows, skip_s, period_s)
            run.stats["health"] = assess(rows, 1.0 / period_s)
        except Exception as exc:  # noqa: BLE001
            log.warning("run %s: stats of its logged ticks failed: %s", run.run_id, exc)
            notes.append(f"its stats could not be computed ({exc})")
    logged = f"{len(rows)} ticks logged" + (
        f" (to t = {rows[-1]['t_s']:.2f} s)" if rows and rows[-1].get("t_s") is not None else ""
    )
    run.state = "interrupted"
    run.reason = (
        "the server stopped during the run (killed or crashed) and the run never ended; "
        f"stats from the {logged}" + "".join(f"; {note}" for note in notes)
    )
    run.ended_at = last_written  # when its logs were last written
    run.save()
    return rows if run.stats else []


def draw_report(run: Run, rows: list[dict[str, Any]], skip_s: float, period_s: float) -> None:
    """Draw a recovered run's report from its logged ``rows`` (seconds of matplotlib, so the
    manager does it after start-up, in a thread) and save the record with ``has_report``."""
    try:
        reason = "the server stopped during the run"
        write_report(run.folder, rows, run, run.stats, reason, skip_s, period_s, "interrupted")
        run.has_report = True
        run.write()
    except Exception as exc:  # noqa: BLE001 - a report that fails must not stop the server
        log.warning("run %s: its report could not be drawn: %s", run.run_id, exc)

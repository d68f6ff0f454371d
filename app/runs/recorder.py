"""Recording one run: a listener in the control thread feeds a writer thread.

The control thread only appends to a queue; the writer thread writes the logs, keeps the
samples for the statistics and, when the run ends (finished, aborted, e-stop or fault),
closes the files, computes the stats and draws the report.

A run's log is bounded: a run is planned within ``runs.max_samples`` loop periods, and
while a program stands (Pause, M0, M1, a single step's stop: its time rate 0) the
recorder keeps one row a second (``PAUSED_ROW_EVERY_S``, marked with why it stands in
``paused``), plus every tick the loop's health needs (an overrun, a stale reading, a
fault, a long gap, and the tick after one); a pause longer than ``runs.max_pause_s``
aborts the run, saying so. Standing, a run writes at most ``max_pause_s`` rows a pause
(plus those unhealthy ticks) instead of 200 a second without end.
"""

from __future__ import annotations

import atexit
import math
import queue
import shutil
import threading
import time
import weakref
from typing import TYPE_CHECKING, Any

import numpy as np

from app.control.state import Snapshot
from app.runs.health import assess
from app.runs.logs import RunLog
from app.runs.report import write_report
from app.runs.run import Run
from app.runs.stats import angle_stats, error_stats, line_stats, window_mask

if TYPE_CHECKING:
    from app.control.controller import Controller
    from app.runs.source import TrajectorySource

_END = object()
PAUSED_ROW_EVERY_S = 1.0  # while a program stands: one row a second [s]


def _values(vector: np.ndarray) -> list[float | None]:
    return [None if not math.isfinite(v) else float(v) for v in vector.tolist()]


def row_of(snap: Snapshot, t_s: float) -> dict[str, Any]:
    """One log row (see logs.COLUMNS) from a tick's snapshot."""
    row: dict[str, Any] = {"t_s": t_s, "phase": snap.phase, "mode": snap.mode}
    for prefix, vector, names in (
        ("goal", snap.goal_m, "xyz"),
        ("commanded", snap.joints_commanded_rad, "123"),
        ("measured", snap.joints_measured_rad, "123"),
        ("measured", snap.point_measured_m, "xyz"),
    ):
        unit = "m" if names == "xyz" else "rad"
        letter = "" if names == "xyz" else "q"
        for name, value in zip(names, _values(vector), strict=True):
            row[f"{prefix}_{letter}{name}_{unit}"] = value
    for name, value in zip("xyz", _values(snap.external_m), strict=True):
        row[f"external_{name}_m"] = value
    row["lateness_ms"] = snap.lateness_ms
    row["faults"] = "; ".join(f.reason for f in snap.faults)
    extra = snap.extra or {}
    for kind in ("goal", "measured"):
        values = extra.get(f"{kind}_world_m") or [None] * 3
        for name, value in zip("xyz", values, strict=True):
            row[f"world_{kind}_{name}_m"] = value
    row["outside"] = extra.get("outside")
    age = extra.get("pose_age_s")
    row["pose_age_ms"] = None if age is None else age * 1e3
    row["gap_ms"] = snap.gap_ms  # the loop's health (app/runs/health.py) reads these four
    row["overrun"] = snap.overrun
    row["sim_time_s"] = _values(np.array([snap.sim_time_s]))[0]
    row["stale"] = snap.stale
    row["feedback_age_ms"] = snap.feedback_age_ms
    row["line"] = None  # a program's line: set by the recorder from its source
    for kind in ("goal", "commanded", "measured"):  # NaN (no wrist) is logged empty
        row[f"phi_{kind}_rad"] = _values(np.array([getattr(snap, f"phi_{kind}_rad")]))[0]
    row["world_heading_goal_rad"] = extra.get("heading_world_rad")
    row["world_heading_measured_rad"] = extra.get("measured_heading_world_rad")
    row["heading_limited"] = extra.get("heading_limited")
    row["paused"] = None  # a program standing or braking to: set by the recorder
    for name, value in zip("xyz", _values(snap.contact.force_n), strict=True):
        row[f"contact_force_{name}_n"] = value  # NaN (not known) is logged empty
    row["contact_valid"] = bool(snap.contact.valid)
    return row


def pause_reason(paused_s: float, limit_s: float, why: str) -> str:
    """The abort reason of a run paused ``paused_s`` [s], over ``limit_s`` [s]."""
    return (
        f"paused {paused_s:.0f} s ({why}), over the limit of {limit_s:.0f} s "
        "(runs.max_pause_s): aborted so its log stays bounded"
    )


def needed_for_health(snap: Snapshot, period_s: float) -> bool:
    """A tick the loop's health is judged on (app/runs/health.py): an overrun, a stale
    reading, a fault, or a gap over two loop periods ``period_s`` [s]."""
    gap = snap.gap_ms
    long_gap = gap is not None and math.isfinite(gap) and gap > 2e3 * period_s
    return bool(snap.overrun or snap.stale or snap.faults or long_gap)


def _column(rows: list[dict[str, Any]], name: str) -> np.ndarray:
    return np.array([np.nan if r.get(name) is None else r[name] for r in rows], dtype=float)


def _wrapped(angle_rad: np.ndarray) -> np.ndarray:
    return (angle_rad + np.pi) % (2 * np.pi) - np.pi


def _columns(rows: list[dict[str, Any]], prefix: str) -> np.ndarray:
    return np.array([[r[f"{prefix}_{a}_m"] for a in "xyz"] for r in rows], dtype=float)


def run_stats(
    rows: list[dict[str, Any]], skip_s: float, dt_s: float, lines_met: list[int] | None = None
) -> dict[str, Any]:
    """Tracking stats (goal vs FK) over the test part, world stats for hold runs and, for a
    G-code program (rows with a ``line``), ``program.lines``: the error per program line
    over every sample of the timed part (app/runs/stats.py line_stats). ``lines_met``: the
    lines the source met in order (TrajectorySource.lines_met); one no sample shows (crossed
    whole between two ticks) is listed with 0 samples and no error (None)."""
    times = np.array([r["t_s"] for r in rows])
    active = np.array([r["phase"] in ("timed", "hold") for r in rows], dtype=bool)
    if active.any():  # the approach and the first moments are not the test
        active &= window_mask(times, float(times[active][0]) + skip_s, None)
    stats: dict[str, Any] = {
        "tracking": error_stats(_columns(rows, "goal"), _columns(rows, "measured"), active)
    }
    external = _columns(rows, "external")
    if np.isfinite(external).any():  # thesis Table 6.2: FK against the external measurement
        stats["validation"] = error_stats(_columns(rows, "measured"), external, active)
    world_measured = _columns(rows, "world_measured")
    if np.isfinite(world_measured).any():
        world = error_stats(_columns(rows, "world_goal"), world_measured, active)
        outside = np.array([bool(r["outside"]) for r in rows])
        world["outside_s"] = float(np.sum(outside & active) * dt_s)
        world["inside_only"] = error_stats(
            _columns(rows, "world_goal"), world_measured, active & ~outside
        )
        heading = _column(rows, "world_heading_goal_rad")
        if np.isfinite(heading).any():  # with a wrist: the tool's world heading
            error = _wrapped(heading - _column(rows, "world_heading_measured_rad"))
            world["heading"] = angle_stats(error, active)
            limited = np.array([bool(r.get("heading_limited")) for r in rows])
            world["heading"]["limited_s"] = float(np.sum(limited & active) * dt_s)
        stats["world"] = world
    phi_goal = _column(rows, "phi_goal_rad")
    if np.isfinite(phi_goal).any():  # a wrist: its goal against its reading
        stats["wrist"] = angle_stats(phi_goal - _column(rows, "phi_measured_rad"), active)
    lines = [r.get("line") for r in rows]
    if any(v is not None for v in lines):  # a G-code program: the error per line, every
        timed = np.array([r["phase"] == "timed" for r in rows], dtype=bool)  # sample of it
        error = _columns(rows, "goal") - _columns(rows, "measured")
        kept = [v if t else None for v, t in zip(lines, timed, strict=True)]
        per_line = line_stats(np.array(kept, dtype=object), error)
        stats["program"] = {"lines": with_unsampled(per_line, lines_met or [])}
    return stats


def with_unsampled(per_line: list[dict[str, Any]], lines_met: list[int]) -> list[dict[str, Any]]:
    """``per_line`` (line_stats' entries) with an entry of 0 samples and no error for each
    line in ``lines_met`` that has none, in the order the lines were met."""
    sampled = {e["line"]: e for e in per_line}
    order = list(dict.fromkeys([*lines_met, *sampled]))  # met first; then any others
    empty = {"samples": 0, "rmse_m": None, "max_m": None}
    return [sampled.get(line, {"line": line, **empty}) for line in order]


# Recorders whose writer thread still runs. After its run ends a recorder draws the report
# (matplotlib, native code) in that daemon thread; a process that exits meanwhile crashed
# in finalization ("terminate called without an active exception", after every test had
# passed), so the server's shutdown and the interpreter's exit wait for them.
_LIVE: weakref.WeakSet[Recorder] = weakref.WeakSet()


@atexit.register
def wait_for_recorders(timeout_s: float = 60.0) -> None:
    """Wait up to ``timeout_s`` [s] for every recorder's logs and report to be written."""
    for recorder in list(_LIVE):
        recorder.join(timeout_s)


class Recorder:
    """Feeds one run's ticks from the controller to its logs; finalises the run at the end."""

    def __init__(
        self, run: Run, controller: Controller, source: TrajectorySource, log: RunLog, skip_s: float
    ) -> None:
        self.run, self.controller, self.source, self.log = run, controller, source, log
        self.skip_s = skip_s
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._t0: float | None = None
        self._rows: list[dict[str, Any]] = []
        self.max_pause_s = controller.settings.runs.max_pause_s
        self._standing_since: float | None = None  # loop time the program stood from [s]
        self._kept_at = -math.inf  # loop time of the last row kept while standing [s]
        self._after_unhealthy = False  # the previous tick was one health needs
        self._pause_aborted = False
        self._thread = threading.Thread(target=self._write, name=f"run-{run.run_id}", daemon=True)
        _LIVE.add(self)
        self._thread.start()

    def join(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` [s] for the logs and the report (any thread)."""
        if self._thread is not threading.current_thread():
            self._thread.join(timeout_s)

    # control thread
    def on_tick(self, snap: Snapshot) -> None:
        active = self.controller.current_source is self.source
        if self._t0 is None and not active:
            return  # registered before the loop has taken the source up
        if not active:
            self.controller.remove_listener(self.on_tick)
            reason = None if self.source.finished else self._why_stopped(snap)
            self._queue.put((_END, reason))
            return
        if self._t0 is None:
            self._t0 = snap.time_s
            self.log.start_ns = time.time_ns()  # log times: UTC wall clock of this tick
        if not self._keep(snap):
            return
        row = row_of(snap, snap.time_s - self._t0)
        row["line"] = getattr(self.source, "program_line", None)  # a G-code program's line
        feed = getattr(self.source, "feed_state", None)
        row["paused"] = None if feed is None else feed.paused
        self._queue.put((row, snap))  # the snapshot too: the ROS 2 log's messages

    def _keep(self, snap: Snapshot) -> bool:
        """Whether this tick becomes a row: every tick while the run moves; standing, one
        a second and those the loop's health needs (and the tick after each). A stand
        longer than max_pause_s stops the run (once; the run ends at the next ticks)."""
        feed = getattr(self.source, "feed_state", None)
        unhealthy = needed_for_health(snap, self.controller.period_s)
        after, self._after_unhealthy = self._after_unhealthy, unhealthy
        if feed is None or feed.paused is None or feed.rate != 0.0:
            self._standing_since = None
            return True
        now = snap.time_s
        if self._standing_since is None:
            self._standing_since, self._kept_at = now, -math.inf
        standing_s = now - self._standing_since
        if standing_s > self.max_pause_s and not self._pause_aborted:
            self._pause_aborted = True
            if self.run.abort_reason is None:
                self.run.abort_reason = pause_reason(standing_s, self.max_pause_s, feed.paused)
            self.controller.stop_source(self.source)  # queued: the loop stops it next
        if now - self._kept_at >= PAUSED_ROW_EVERY_S - 1e-9:
            self._kept_at = now
            return True
        return unhealthy or after

    def _why_stopped(self, snap: Snapshot) -> str:
        if snap.estopped:
            return "e-stop"
        if snap.faults:
            return f"fault: {snap.faults[0].reason}"
        if self.run.abort_reason is None and (snap.notice or "").startswith("stopped: "):
            return snap.notice.removeprefix("stopped: ")  # e.g. the station's link was lost
        return self.run.abort_reason or "stopped by another command"

    def discard(self) -> None:
        """The run never started: close the files and remove its folder."""
        self._queue.put((_END, "did not start"))
        self._thread.join(timeout=5.0)
        shutil.rmtree(self.run.folder, ignore_errors=True)

    # writer thread
    def _write(self) -> None:
        try:
            while True:
                item = self._queue.get()
                if isinstance(item, tuple) and item[0] is _END:
                    self._finish(item[1])
                    return
                row, snap = item
                self.log.write(row, snap)
                self._rows.append(row)
        finally:
            _LIVE.discard(self)

    def _finish(self, abort_reason: str | None) -> None:
        self.log.close()
        if not self._rows:
            self.run.finish({}, abort_reason, 0)
            self.run.save()
            return
        stats = run_stats(
            self._rows,
            self.skip_s,
            self.controller.period_s,
            getattr(self.source, "lines_met", None),
        )
        stats["health"] = assess(self._rows, self.controller.settings.loop.rate_hz)
        # The record is final before the report is drawn (seconds of matplotlib on a loaded
        # machine): the run has ended, so it must not hold the robot's next run back.
        self.run.finish(stats, abort_reason, len(self._rows))
        try:
            self.run.write()
            write_report(
                self.run.folder,
                self._rows,
                self.run,
                stats,
                abort_reason,
                self.skip_s,
                self.controller.period_s,
            )
            self.run.has_report = True
        finally:
            self.run.save()

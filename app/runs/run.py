"""The record of one run: what was asked, under which conditions, how it ended.

Shared by the run manager (which creates, lists and finds runs) and the recorder (which
finishes them); it imports neither.

The record is ``run.json`` beside the logs, written when the run starts (state
``running``), rewritten as it goes (``samples``, at most every ``SAVE_EVERY_S``) and at
its end; each write replaces the file whole (a temporary file renamed over it), so a
crash leaves the last complete record, never half of one.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from dataclasses import dataclass, field, fields
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, ClassVar

log = logging.getLogger(__name__)

SAVE_EVERY_S = 1.0  # how often a running run's record is rewritten with its sample count
STATES = ("running", "done", "aborted", "interrupted")


def utc_iso(unix_s: float) -> str:
    """ISO 8601 UTC time of a Unix time [s], to the millisecond: 2026-12-01T09:30:00.123Z."""
    moment = datetime.fromtimestamp(unix_s, tz=UTC).isoformat(timespec="milliseconds")
    return moment.replace("+00:00", "Z")


@dataclass
class Run:
    """One execution of a test trajectory; saved as run.json beside its logs."""

    run_id: str
    kind: str
    params: dict[str, Any]
    conditions: dict[str, Any]
    folder: Path
    state: str = "running"  # one of STATES
    reason: str | None = None
    started_at: float = field(default_factory=time.time)
    started_at_utc: str = ""  # started_at in UTC, ISO 8601 (set from started_at if empty)
    ended_at: float | None = None
    samples: int = 0
    stats: dict[str, Any] = field(default_factory=dict)
    has_report: bool = False
    abort_reason: str | None = None
    done: threading.Event = field(default_factory=threading.Event, repr=False)
    _saved_at: float = field(default=float("-inf"), repr=False)

    # not in run.json: where it is, the waiters' event, internals
    HIDDEN: ClassVar[frozenset[str]] = frozenset({"folder", "done", "abort_reason", "_saved_at"})

    def __post_init__(self) -> None:
        if not self.started_at_utc:
            self.started_at_utc = utc_iso(self.started_at)

    @classmethod
    def load(cls, path: Path) -> Run:
        """The run saved in ``path`` (its run.json); keys this version does not know are
        left out. Raises OSError, ValueError (bad JSON) or TypeError (fields missing)."""
        data = json.loads(path.read_text())
        if not isinstance(data, dict):
            raise ValueError(f"{path}: not a JSON object")
        known = {f.name for f in fields(cls)} - cls.HIDDEN
        return cls(**{k: v for k, v in data.items() if k in known}, folder=path.parent)

    def finish(self, stats: dict[str, Any], abort_reason: str | None, samples: int) -> None:
        self.stats = stats
        self.state, self.reason = ("aborted", abort_reason) if abort_reason else ("done", None)
        self.samples, self.ended_at = samples, time.time()

    def as_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in self.HIDDEN}

    def write(self) -> None:
        """Replace run.json with the record as it is now (atomically); raises OSError."""
        path = self.folder / "run.json"
        temporary = path.with_name("run.json.tmp")
        temporary.write_text(json.dumps(self.as_dict(), indent=1))
        os.replace(temporary, path)
        self._saved_at = time.monotonic()

    def progress(self, samples: int) -> None:
        """``samples`` are in the logs now (the writer's thread, after each flush): the
        live count, saved to run.json at most every SAVE_EVERY_S. A failed save is logged,
        never raised: the run goes on and its end is saved again."""
        self.samples = samples
        if time.monotonic() - self._saved_at < SAVE_EVERY_S:
            return
        try:
            self.write()
        except OSError as exc:
            log.warning("run %s: could not save its record: %s", self.run_id, exc)

    def save(self) -> None:
        """The final record: written, then the run is marked done for waiters."""
        try:
            self.write()
        finally:
            self.done.set()

"""The record of one run: what was asked, under which conditions, how it ended.

Shared by the run manager (which creates, lists and finds runs) and the recorder (which
finishes them); it imports neither.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any


@dataclass
class Run:
    """One execution of a test trajectory; saved as run.json beside its logs."""

    run_id: str
    kind: str
    params: dict[str, Any]
    conditions: dict[str, Any]
    folder: Path
    state: str = "running"  # running | done | aborted
    reason: str | None = None
    started_at: float = field(default_factory=time.time)
    ended_at: float | None = None
    samples: int = 0
    stats: dict[str, Any] = field(default_factory=dict)
    has_report: bool = False
    abort_reason: str | None = None
    done: threading.Event = field(default_factory=threading.Event, repr=False)

    @property
    def title(self) -> str:
        if self.kind == "hold":
            on = self.params.get("latency_compensation")
            return f"run {self.run_id}: hold in world (latency compensation {on}), world frame"
        return f"run {self.run_id}: {self.kind}, feed-forward {self.params.get('feedforward')}"

    def finish(self, stats: dict[str, Any], abort_reason: str | None, samples: int) -> None:
        self.stats = stats
        self.state, self.reason = ("aborted", abort_reason) if abort_reason else ("done", None)
        self.samples, self.ended_at = samples, time.time()

    def as_dict(self) -> dict[str, Any]:
        hidden = {"folder", "done", "abort_reason"}
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in hidden}

    def save(self) -> None:
        (self.folder / "run.json").write_text(json.dumps(self.as_dict(), indent=1))
        self.done.set()

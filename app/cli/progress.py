"""Progress of long work on stderr: a tqdm bar on a terminal, percentage lines otherwise.

A pipe or a CI log gets one line per phase and one at every ``step`` percent, never the
bar's carriage returns; stdout stays for the result (``--json`` stays parseable).
"""

from __future__ import annotations

import sys
from typing import Any, TextIO


class Progress:
    """How far ``total`` units of work are (``unit``: "s", "gen"...), shown on ``stream``.

    Use as a context manager; call :meth:`update_to` with the work done so far (absolute,
    not a step) and, optionally, the phase it is in and a note (e.g. the best objective).
    """

    def __init__(
        self,
        total: float,
        desc: str,
        unit: str,
        stream: TextIO | None = None,
        step_percent: int = 10,
    ) -> None:
        self.total = max(float(total), 1e-9)
        self.desc, self.unit, self.step = desc, unit, step_percent
        self.stream = sys.stderr if stream is None else stream
        self._bar: Any = None
        self._percent = -1  # last percentage line written
        self._phase: str | None = None
        isatty = getattr(self.stream, "isatty", None)
        if isatty is not None and isatty():
            from tqdm import tqdm

            fmt = "{l_bar}{bar}| {n:.1f}/{total:.1f} " + unit + " [{elapsed}<{remaining}{postfix}]"
            self._bar = tqdm(total=self.total, desc=desc, file=self.stream, bar_format=fmt)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def update_to(
        self,
        done: float,
        phase: str | None = None,
        note: str | None = None,
        total: float | None = None,
    ) -> None:
        """``done`` of ``total`` units are finished; ``phase`` names the current part;
        ``total`` changes the length when it becomes known."""
        if total is not None and total > 0:
            self.total = float(total)
            if self._bar is not None:
                self._bar.total = self.total
        done = min(max(float(done), 0.0), self.total)
        if self._bar is not None:
            self._bar.update(done - self._bar.n)
            if phase or note:
                self._bar.set_postfix_str(" ".join(p for p in (phase, note) if p))
            return
        percent = int(100 * done / self.total) // self.step * self.step
        if percent > self._percent or (phase and phase != self._phase):
            self._percent, self._phase = max(percent, self._percent), phase or self._phase
            parts = [f"{self.desc}: {percent}% ({done:.1f} of {self.total:.1f} {self.unit})"]
            parts += [p for p in (phase, note) if p]
            print(", ".join(parts), file=self.stream, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

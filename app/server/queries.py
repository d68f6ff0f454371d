"""Workspace queries out of the loop's process: the nearest accepted point and sections.

``sections.nearest`` (the page's "nearest", ``GET /api/workspace/nearest``, the 422 of a
refused goal) is up to seconds of NumPy and Python for a far point, and
``sections.section`` a few hundred ms for a new level; run in the server's process they
hold the GIL the 200 Hz loop needs: four clients asking for far points pulled the loop
from ~160 Hz to 104-135 Hz (issue 28). So :class:`WorkspaceQueries` runs them in worker
processes (``app.programs.workers.ProgramWorkers``: spawned, not niced, killed past a
bound) with at most ``slots`` (one: the other core stays the loop's) at a time, a few
more waiting their turn (the page asks for three sections and a nearest point at once),
and keeps the last answers (a repeated query costs a dictionary look-up):

- a query beyond the queue is refused at once, and one that waited ``wait_s`` in it is
  refused then (:class:`QueriesBusy`: the route answers 503 with Retry-After; a refused
  goal's 422 falls back to the gate's own nearest workspace point, computed with the
  refusal, so it is still a 422); waiting costs the loop's process no CPU, and the queue
  is short so that waiting requests never fill the server's thread pool;
- a query that takes longer than ``timeout_s`` has its worker killed (503).

No request can make the loop's process do more than look up or hand over a query.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np

from app.config import Settings
from app.control.gate import Gate
from app.programs import workers
from app.programs.workers import ChecksBusy, ProgramWorkers, WorkerError
from app.server import sections

# a worker unpickles sections.nearest by importing app.server.sections, and with it the
# app.server package (the whole server): ~2 s per worker unless the fork server has it
workers.preload(sections.__name__)

SLOTS = 1  # worker processes at once (~150 MB; one core stays the loop's); a second is refused
TIMEOUT_S = 60.0  # the longest a query may take, its worker's start included [s]
# the worker's niceness: not lowered, since a person waits for the answer and a niced
# worker beside other busy processes took over 20 s; one worker leaves a core to the loop
NICE = 0
CACHE_SIZE = 512  # answers kept (a section is ~30 kB)
QUEUE = 4  # queries that may wait for the worker (the page asks for 3 sections at once)
WAIT_S = 15.0  # the longest a query waits for the worker before it is refused [s]


class QueriesBusy(WorkerError):
    """The worker and every place in its queue are taken, or the wait for the worker ran
    out (503, Retry-After)."""


BUSY = "busy: the server is answering other workspace queries; try again shortly"


class WorkspaceQueries:
    """The workspace queries of the server's routes, in worker processes (see the module
    docstring). Blocking methods: call them from a worker thread (``asyncio.to_thread``).
    Raises QueriesBusy or another WorkerError (the message says why) besides what the
    query raises itself (ValueError)."""

    def __init__(
        self,
        settings: Settings,
        slots: int = SLOTS,
        timeout_s: float = TIMEOUT_S,
        queue: int = QUEUE,
        wait_s: float = WAIT_S,
    ):
        self._workers = ProgramWorkers(settings, slots, timeout_s, nice=NICE)
        self._slots = threading.Semaphore(slots)  # queries in a worker
        self._places = threading.Semaphore(slots + queue)  # in a worker or waiting for one
        self.wait_s = wait_s
        self._answers: OrderedDict[tuple, tuple[Gate, Any]] = OrderedDict()
        self._lock = threading.Lock()
        self.asked = 0  # queries answered in a worker (not from the kept answers)

    def nearest(self, gate: Gate, point: np.ndarray, phi: float = 0.0) -> np.ndarray:
        """``sections.nearest(gate, point, phi)``: (3,) [m] for a (3,) tip [m]."""
        key = ("nearest", id(gate), *(float(v) for v in point), float(phi))
        return self._ask(key, gate, sections.nearest, np.asarray(point, dtype=np.float64), phi)

    def section(self, gate: Gate, plane: str, at_m: float, phi: float) -> sections.Section:
        """``sections.section(gate, plane, at_m, phi)`` (its own rounding is the key)."""
        level = round(at_m / sections.LEVEL_STEP_M)
        turn = round(phi / sections.PHI_STEP_RAD)
        key = ("section", id(gate), plane, level, turn)
        return self._ask(key, gate, sections.section, plane, at_m, phi)

    def _ask(self, key: tuple, gate: Gate, query: Callable[..., Any], *args: Any) -> Any:
        with self._lock:
            kept = self._answers.get(key)
            if kept is not None and kept[0] is gate:  # the same gate object, not a reused id
                self._answers.move_to_end(key)
                return kept[1]
        answer = self.call(query, gate, *args)
        with self._lock:
            self.asked += 1
            self._answers[key] = (gate, answer)
            while len(self._answers) > CACHE_SIZE:
                self._answers.popitem(last=False)
        return answer

    def call(self, function: Callable[..., Any], *args: Any) -> Any:
        """``function(*args)`` in the worker, through the queue (what every query takes;
        tests give their own module-level function). Raises QueriesBusy (no place in the
        queue, or the wait ran out, or the server is stopping) or WorkerError (the worker
        overran or died)."""
        if not self._places.acquire(blocking=False):  # a flood: refused at once
            raise QueriesBusy(BUSY)
        try:
            if not self._slots.acquire(timeout=self.wait_s):
                raise QueriesBusy(BUSY)
            try:
                answer = self._workers.call(function, *args)
            finally:
                self._slots.release()
        except QueriesBusy:
            raise
        except ChecksBusy:  # closed: the server is stopping
            raise QueriesBusy("the server is stopping: no workspace queries now") from None
        except WorkerError as exc:  # its worker overran (killed) or died
            kind = "took too long" if "longer" in str(exc) else "ended before answering"
            raise WorkerError(
                f"the workspace query {kind} (its worker was stopped); try again"
            ) from None
        finally:
            self._places.release()
        return answer

    def close(self) -> None:
        """Kill the workers (the server stopping); later queries are QueriesBusy."""
        self._workers.close()

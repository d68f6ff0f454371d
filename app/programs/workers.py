"""Program checks and dry runs in worker processes, away from the control loop.

A check is seconds of CPU, much of it Python that holds the GIL: in the server's own
process it held the 200 Hz loop up to 77.5 ms (benchmarks/gcode_check_loop.py,
docs/performance.md). So the server hands each check and dry run to a worker process:
only picklable things cross (the program's text, the settings, the gate in force, the
start point and the G54 offset in; a :class:`CheckedProgram`, a :class:`DryRun` or the
:class:`ProgramError` / :class:`DryRunRefused` raised there out).

:class:`ProgramWorkers` has ``slots`` slots (2 by default), each a
``ProcessPoolExecutor`` of one worker process, started on the slot's first job and kept
for the next ones. Workers are forked from a fork server (``forkserver``, where the
platform has it; else ``spawn``): a clean process of its own, without the server's
threads (a fork of the server could inherit a lock another thread held), that imported
this module and its numerical stack once; a new worker then costs a fork and the gate's
projection (~0.35 s on the 2-core VM) instead of a fresh interpreter's imports (~0.9 s
quiet, seconds on a loaded machine). A worker runs at a lower priority (nice +10: on a loaded
machine the loop gets the CPU first), ignores SIGINT (the server stops it) and pays the
gate's workspace projection once, when it starts. When every slot is busy another job is
refused at once (:class:`ChecksBusy`, nothing is queued). A job that takes longer than
``timeout_s`` has its worker killed (:class:`WorkerTimeout`); a worker that dies (killed,
out of memory) ends its job with :class:`WorkerCrashed`; either way the slot starts a new
worker for its next job. :meth:`ProgramWorkers.close` (the server stopping: at the start of
its shutdown, so a check in flight does not hold it) kills every worker: their jobs end at
once with :class:`ChecksStopped`, later ones are refused (:class:`ChecksBusy`).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import threading
from collections.abc import Callable
from concurrent.futures import CancelledError as FutureCancelled
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from app.config import Settings
from app.control.commands import CommandContext
from app.control.gate import Gate
from app.programs.check import CheckedProgram, check_program
from app.programs.dry_run import DryRun, dry_run

WORKER_NICE = 10  # added to a worker's niceness: the control loop's process comes first


_PRELOAD = [__name__]  # what the fork server imports once, before its first fork


def _worker_context() -> multiprocessing.context.BaseContext:
    """The fork server, preloaded with this module (the module doc); spawn without one."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(_PRELOAD)
    return context


WORKERS = _worker_context()  # never a fork of the server's own process: it has threads


def preload(*modules: str) -> None:
    """Have the fork server import ``modules`` (dotted names) too, so that no worker pays
    for them: those of the functions its callers send (a worker imports a function's
    module to unpickle it). Effective before the fork server's first start (the first
    job of any ``ProgramWorkers`` in this process); no effect under ``spawn``."""
    _PRELOAD.extend(name for name in modules if name not in _PRELOAD)
    if WORKERS.get_start_method() == "forkserver":
        WORKERS.set_forkserver_preload(_PRELOAD)  # type: ignore[attr-defined]


T = TypeVar("T")


class WorkerError(RuntimeError):
    """A job that did not come back from its worker; the message says why (an HTTP 503)."""


class ChecksBusy(WorkerError):
    """Every slot is running a job: refused at once, nothing is queued."""


class WorkerCrashed(WorkerError):
    """The worker process ended before answering (killed, out of memory)."""


class WorkerTimeout(WorkerError):
    """The job took longer than the bound: its worker was killed."""


class ChecksStopped(WorkerCrashed):
    """:meth:`ProgramWorkers.close` (the server stopping) killed the job's worker, or came
    between the job's slot and its start: the job was abandoned."""


STOPPING = "the server is stopping: no program checks now"


@dataclass(frozen=True)
class CheckJob:
    """What a check needs, all picklable: the arguments of :func:`check_program`.

    text: the program; settings: the robot and limits; gate: the limits in force (the
    controller's); start_m, work_offset_m (3,) [m] and near (3,) [rad] or None (the
    settings' defaults); for_run: the program is about to run (refused beyond
    runs.max_samples before the costly checks).
    start_phi_rad: the wrist's angle at the start [rad] (0 without a wrist).
    """

    text: str
    settings: Settings
    gate: Gate | None = None
    start_m: np.ndarray | None = None
    work_offset_m: tuple[float, float, float] | None = None
    near: np.ndarray | None = None
    for_run: bool = False
    start_phi_rad: float = 0.0


def run_check(job: CheckJob) -> CheckedProgram:
    """The check, in the worker (raises ProgramError as :func:`check_program` does)."""
    return check_program(
        job.text,
        job.settings,
        gate=job.gate,
        start_m=job.start_m,
        work_offset_m=job.work_offset_m,
        near=job.near,
        for_run=job.for_run,
        start_phi_rad=job.start_phi_rad,
    )


def run_dry_run(job: CheckJob, feedforward: bool) -> tuple[CheckedProgram, DryRun]:
    """The check, then the dry run on the worker's own headless twin (raises
    ProgramError or DryRunRefused)."""
    checked = run_check(job)
    return checked, dry_run(checked, job.settings, feedforward=feedforward, gate=job.gate)


def _start_worker(settings: Settings, nice: int = WORKER_NICE) -> None:
    """A new worker: lower priority, SIGINT left to the server, the gate's first workspace
    projection paid now (cached per process by kinematics.projection)."""
    with contextlib.suppress(OSError):
        if nice:
            os.nice(nice)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    CommandContext.from_settings(settings)


def _alive(executor: ProcessPoolExecutor) -> bool:
    """Whether ``executor`` can take a job: not broken, and no worker of it has died (a
    worker killed while idle breaks the pool only when the next job finds it)."""
    if getattr(executor, "_broken", False):
        return False
    processes = getattr(executor, "_processes", None) or {}
    return all(process.is_alive() for process in processes.values())


def _kill(executor: ProcessPoolExecutor) -> None:
    """Stop ``executor`` and kill its worker (busy or not); returns without waiting."""
    # killed first: a shutdown alone would let an idle worker exit on its own, and a busy
    # one finish its job (ProcessPoolExecutor has no public kill before Python 3.14)
    for process in list((getattr(executor, "_processes", None) or {}).values()):
        with contextlib.suppress(OSError, ValueError):
            process.kill()
    executor.shutdown(wait=False, cancel_futures=True)


class ProgramWorkers:
    """Checks and dry runs in worker processes, at most ``slots`` at a time.

    Args:
        settings: passed to each worker when it starts (to warm the gate's projection).
        slots: jobs running at once (each a worker process of up to ~1 GB in a long check).
        timeout_s: the longest a job may take, its worker's start included [s].
        nice: added to each worker's niceness (WORKER_NICE: the loop's process first;
            0 for short queries a person waits for, which a busy machine would starve).

    The methods block the calling thread (a request's) until the answer, and raise
    ChecksBusy, WorkerCrashed or WorkerTimeout (each a WorkerError) besides what the job
    itself raises. Safe from any thread. :meth:`close` kills the workers.
    """

    def __init__(
        self,
        settings: Settings,
        slots: int = 2,
        timeout_s: float = 300.0,
        nice: int = WORKER_NICE,
    ) -> None:
        self.settings, self.slots, self.timeout_s = settings, slots, timeout_s
        self.nice = nice
        self._lock = threading.Lock()
        self._free = list(range(slots))
        self._executors: list[ProcessPoolExecutor | None] = [None] * slots
        self._closed = False

    def check(self, job: CheckJob) -> CheckedProgram:
        """:func:`run_check` in a worker."""
        return self.call(run_check, job)

    def dry_run(self, job: CheckJob, feedforward: bool) -> tuple[CheckedProgram, DryRun]:
        """:func:`run_dry_run` in a worker."""
        return self.call(run_dry_run, job, feedforward)

    def call(self, function: Callable[..., T], *args: Any) -> T:
        """``function(*args)`` in a free slot's worker: a module-level function and
        picklable arguments and result (what ``check`` and ``dry_run`` use; tests give
        their own)."""
        slot = self._take()
        try:
            future = self._submit(slot, function, args)
            try:
                return future.result(timeout=self.timeout_s)
            except FutureTimeout:
                self._discard(slot)
                if self._closed:
                    raise self._stopped() from None
                raise WorkerTimeout(
                    f"the program's check took longer than {self.timeout_s:g} s "
                    "(programs.check_timeout_s): its worker was stopped; a shorter program "
                    "checks faster"
                ) from None
            except (BrokenProcessPool, FutureCancelled):  # cancelled: close() before it ran
                self._discard(slot)
                if self._closed:
                    raise self._stopped() from None
                raise WorkerCrashed(
                    "the worker process checking the program ended before answering "
                    "(killed, or out of memory); the next check starts a new one"
                ) from None
        finally:
            with self._lock:
                self._free.append(slot)

    def _submit(self, slot: int, function: Callable[..., T], args: tuple) -> Future[T]:
        """The job in ``slot``'s worker; ChecksStopped when :meth:`close` came first (the
        executor it shut down refuses new jobs with a bare RuntimeError)."""
        try:
            try:
                return self._executor(slot).submit(function, *args)
            except BrokenProcessPool:  # broken before this job: a fresh worker takes it
                self._discard(slot)
                return self._executor(slot).submit(function, *args)
        except RuntimeError as exc:  # ChecksBusy, BrokenProcessPool and shutdown's alike
            if self._closed:
                raise self._stopped() from None
            if isinstance(exc, BrokenProcessPool):
                raise WorkerCrashed(
                    "the worker process for the program's check could not start; "
                    "the next check tries a new one"
                ) from None
            raise

    @staticmethod
    def _stopped() -> ChecksStopped:
        return ChecksStopped(
            "the server is stopping: the program's check was abandoned (its worker "
            "stopped); check again once the server is back"
        )

    def close(self) -> None:
        """Kill every worker: a job running ends with ChecksStopped (its caller answers at
        once, it does not wait for the job); later jobs are ChecksBusy. Safe to repeat."""
        with self._lock:
            self._closed = True
            executors, self._executors = self._executors, [None] * self.slots
        for executor in executors:
            if executor is not None:
                _kill(executor)

    def _take(self) -> int:
        with self._lock:
            if self._closed:
                raise ChecksBusy(STOPPING)
            if not self._free:
                raise ChecksBusy(
                    f"busy: {self.slots} program checks are running; try again when one has ended"
                )
            return self._free.pop()

    def _executor(self, slot: int) -> ProcessPoolExecutor:
        with self._lock:
            if self._closed:
                raise ChecksBusy(STOPPING)
            executor = self._executors[slot]
            if executor is not None and not _alive(executor):  # its worker died while idle
                self._executors[slot] = None
                _kill(executor)
                executor = None
            if executor is None:  # no process yet: it starts on the first submit
                executor = ProcessPoolExecutor(
                    1,
                    mp_context=WORKERS,
                    initializer=_start_worker,
                    initargs=(self.settings, self.nice),
                )
                self._executors[slot] = executor
            return executor

    def _discard(self, slot: int) -> None:
        with self._lock:
            executor, self._executors[slot] = self._executors[slot], None
        if executor is not None:
            _kill(executor)

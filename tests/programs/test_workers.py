"""Checks in worker processes: the same report as in-process, from another process; the
program's own errors come back as they were raised; a killed or overrunning worker ends
its job with a clear error and the next job gets a new worker; never more than the slots.

Each worker is a spawned Python that imports numpy, MuJoCo and the kinematics and pays the
gate's workspace projection: seconds on a loaded machine, so one pool is shared and every
wait is a condition with a generous bound.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from app.config import load_settings
from app.programs.check import check_program
from app.programs.errors import ProgramError
from app.programs.workers import (
    CheckJob,
    ChecksBusy,
    ChecksStopped,
    ProgramWorkers,
    WorkerCrashed,
    WorkerTimeout,
    run_check,
)
from tests.support.pids import say_pid
from tests.support.wait import wait_for

GOOD = "G21 G90\nG1 F1200 X0 Y0 Z-220\nG2 X10 Y0 I5 J0\nG4 P0.2\nG0 X0\nM2"
START_S = 180.0  # bound on a worker's start (spawn, imports, projection) on a loaded machine

pytestmark = pytest.mark.slow  # worker processes start in seconds


# ---- run in the worker: module-level, so they pickle by name ----


def pid_and_check(job: CheckJob) -> tuple[int, int, object]:
    """The worker's pid and niceness, and its check."""
    return os.getpid(), os.nice(0), run_check(job)


def pid_then_wait(pid_file: str) -> None:
    """Say the worker's pid, then never answer (until killed)."""
    say_pid(pid_file)
    while True:
        time.sleep(1.0)


# ---- helpers ----


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a killed child not yet reaped by its executor is a zombie: not running. Its main
    # thread shows Z while its other threads still exit: dead once it is the last one (only
    # then can its parent reap it, and see it dead; CI's loaded run saw the gap)
    try:
        fields = dict(
            line.split(":\t", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
        )
    except (FileNotFoundError, ProcessLookupError):
        return False
    return not (fields["State"].startswith("Z") and fields["Threads"].strip() == "1")


class Background:
    """``workers.call(pid_then_wait, file)`` in a thread: the worker's pid, the outcome."""

    def __init__(self, workers: ProgramWorkers, pid_file: Path) -> None:
        self.pid_file, self.outcome = pid_file, None
        self.thread = threading.Thread(target=self._call, args=(workers,), daemon=True)
        self.thread.start()

    def _call(self, workers: ProgramWorkers) -> None:
        try:
            workers.call(pid_then_wait, str(self.pid_file))
        except Exception as exc:  # noqa: BLE001 - the outcome under test
            self.outcome = exc

    def pid(self) -> int:
        wait_for(self.pid_file.exists, "the worker to start and say its pid", START_S)
        return int(self.pid_file.read_text())

    def result(self) -> BaseException | None:
        self.thread.join(START_S)
        assert not self.thread.is_alive(), "the call never came back"
        return self.outcome


@pytest.fixture(scope="module")
def settings():
    return load_settings()


@pytest.fixture(scope="module")
def workers(settings) -> Iterator[ProgramWorkers]:
    pool = ProgramWorkers(settings, slots=2, timeout_s=START_S)
    yield pool
    pool.close()


def test_a_check_runs_in_another_process_and_answers_as_in_this_one(workers, settings):
    pid, nice, checked = workers.call(pid_and_check, CheckJob(GOOD, settings))
    assert pid != os.getpid()
    assert nice > os.nice(0) or nice == 19  # the worker yields the CPU to the loop's process
    here = check_program(GOOD, settings)
    assert checked.report == here.report
    assert checked.path.duration_s == here.path.duration_s
    assert workers.check(CheckJob(GOOD, settings)).report == here.report


def test_a_program_error_comes_back_with_its_line_and_word(workers, settings):
    with pytest.raises(ProgramError) as refused:
        workers.check(CheckJob("G21\nG1 F100 X1 A5", settings))
    assert (refused.value.line, refused.value.word) == (2, "A5")
    assert str(refused.value).startswith("line 2: A5: ")


def test_a_killed_worker_is_a_clear_error_and_the_next_check_gets_a_new_one(
    workers, settings, tmp_path
):
    job = Background(workers, tmp_path / "pid")
    pid = job.pid()
    os.kill(pid, signal.SIGKILL)
    crashed = job.result()
    assert isinstance(crashed, WorkerCrashed), crashed
    assert "ended before answering" in str(crashed)
    new_pid, _, checked = workers.call(pid_and_check, CheckJob(GOOD, settings))
    assert checked.report.ok and new_pid not in (pid, os.getpid())


def test_a_worker_killed_while_idle_is_replaced_before_the_next_check(settings):
    """A worker that died between checks (killed, out of memory) must not fail the next
    check that happens to get its slot: that check never ran (an attacker's trial found a
    false 503 here)."""
    pool = ProgramWorkers(settings, slots=1, timeout_s=START_S)
    try:
        pid = pool.call(os.getpid)  # the slot's worker, now idle
        os.kill(pid, signal.SIGKILL)
        wait_for(lambda: not alive(pid), "the idle worker to die")
        new_pid, _, checked = pool.call(pid_and_check, CheckJob(GOOD, settings))
        assert checked.report.ok and new_pid != pid
    finally:
        pool.close()


def test_a_worker_past_its_time_is_stopped_and_the_next_check_gets_a_new_one(settings, tmp_path):
    pool = ProgramWorkers(settings, slots=1, timeout_s=START_S)
    try:
        pid = pool.call(os.getpid)  # its one worker started (the bound below is the job's)
        pool.timeout_s = 0.5  # the job never answers: any bound is passed
        stopped = Background(pool, tmp_path / "pid").result()
        assert isinstance(stopped, WorkerTimeout), stopped
        assert "programs.check_timeout_s" in str(stopped)
        wait_for(lambda: not alive(pid), "the overrunning worker to be killed", START_S)
        pool.timeout_s = START_S
        assert pool.check(CheckJob(GOOD, settings)).report.ok
    finally:
        pool.close()


def test_beyond_the_slots_a_job_is_refused_at_once_and_close_kills_the_workers(settings, tmp_path):
    pool = ProgramWorkers(settings, slots=1, timeout_s=START_S)
    try:
        job = Background(pool, tmp_path / "pid")
        pid = job.pid()
        with pytest.raises(ChecksBusy, match="1 program checks are running"):
            pool.check(CheckJob(GOOD, settings))
    finally:
        pool.close()
    # the job in flight ends at once, saying why (the server stopping, not a crash)
    stopped = job.result()
    assert isinstance(stopped, ChecksStopped), stopped
    assert str(stopped).startswith("the server is stopping")
    wait_for(lambda: not alive(pid), "the worker killed by close", START_S)
    with pytest.raises(ChecksBusy, match="stopping"):
        pool.check(CheckJob(GOOD, settings))


class ClosedBeforeSubmit(ProgramWorkers):
    """A pool whose close() (the server stopping) lands between a job's slot and its
    submit: the executor the job was handed is shut down when the job reaches it."""

    def _executor(self, slot: int):
        executor = super()._executor(slot)
        self.close()
        return executor


def test_a_stop_between_a_jobs_slot_and_its_start_is_said_as_such(settings):
    """A race of the server's shutdown with a request (an attacker's double Ctrl-C): the
    shut-down executor's bare RuntimeError would have been a 500; it is the stopping
    server's WorkerError (a 503 with Retry-After), and the slot is free again."""
    pool = ClosedBeforeSubmit(settings, slots=1, timeout_s=START_S)
    with pytest.raises(ChecksStopped, match="the server is stopping"):
        pool.call(os.getpid)
    assert pool._free == [0]

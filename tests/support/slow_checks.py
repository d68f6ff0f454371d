"""A program check that lasts, for tests of a server stopping with a check in flight.

``install()`` runs in the server's process before it starts (``serve(folder,
preamble=PREAMBLE)``): its program checks become :func:`slow_check`, which the worker
process imports by name. The check says it started (it writes its worker's pid to the
file named by ``$SLOW_CHECK_STARTED``), holds ``HOLD_S`` (far past any test's wait, so a
server that waited for it would be seen waiting), then checks. It gives up holding when
the server that started its worker is gone, so a failed test leaves no process behind.
"""

from __future__ import annotations

import os
import time

from app.programs.check import CheckedProgram
from app.programs.workers import CheckJob, run_check
from tests.support.pids import say_pid

STARTED_ENV = "SLOW_CHECK_STARTED"
HOLD_S = 600.0  # ten times tests.support.server.WAIT_S (not imported: the worker imports this)
PREAMBLE = "import tests.support.slow_checks as slow; slow.install()"


def slow_check(job: CheckJob) -> CheckedProgram:
    """In the worker: say so, hold HOLD_S (or until the server is gone), then check."""
    say_pid(os.environ[STARTED_ENV])
    server, end = os.getppid(), time.monotonic() + HOLD_S
    while time.monotonic() < end and os.getppid() == server:
        time.sleep(0.2)
    return run_check(job)


def install() -> None:
    """In the server's process: ``ProgramWorkers.check`` runs :func:`slow_check`."""
    from app.programs import workers

    workers.run_check = slow_check

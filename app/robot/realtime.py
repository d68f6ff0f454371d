"""Real-time scheduling for the loop's thread, where the OS allows it.

The robot node's control thread asks for ``SCHED_FIFO`` at ``loop.priority`` and, with
``loop.cpu`` set, to run on that CPU alone; both need root or CAP_SYS_NICE (on a drone's
computer: ``setcap cap_sys_nice+ep`` on the Python binary, or run the node as a service
with ``CPUSchedulingPolicy=fifo``; docs/server.md). What it got is in the node's status.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from app.config import LoopSettings


@dataclass(frozen=True)
class Realtime:
    """What the loop's thread got: SCHED_FIFO (and at which priority), the CPUs it may
    run on, and why not where it asked for more."""

    fifo: bool = False
    priority: int = 0
    cpus: tuple[int, ...] = ()
    why_not: str = ""


def share_realtime(realtime: Realtime | None, pid: int | None, below: int = 20) -> bool:
    """Give process ``pid`` (the twin's simulator, whose shared-frame lock the loop waits
    for) SCHED_FIFO ``below`` the loop's priority, when the loop got SCHED_FIFO; False
    when it did not or the OS refused."""
    if realtime is None or not realtime.fifo or pid is None:
        return False
    try:
        os.sched_setscheduler(pid, os.SCHED_FIFO, os.sched_param(max(1, realtime.priority - below)))
    except (OSError, AttributeError):
        return False
    return True


def ask_realtime(loop: LoopSettings) -> Realtime:
    """Ask for SCHED_FIFO and the CPU for the calling thread (the loop's), per ``loop``;
    never raises: what was refused is in ``why_not``."""
    problems: list[str] = []
    fifo, priority = False, 0
    if loop.realtime:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(loop.priority))
            fifo, priority = True, loop.priority
        except (OSError, AttributeError) as exc:
            problems.append(f"SCHED_FIFO refused ({exc}): needs root or CAP_SYS_NICE")
    if loop.cpu is not None:
        try:
            os.sched_setaffinity(0, {loop.cpu})
        except (OSError, AttributeError, ValueError) as exc:
            problems.append(f"CPU {loop.cpu} refused ({exc})")
    try:
        cpus = tuple(sorted(os.sched_getaffinity(0)))
    except AttributeError:
        cpus = ()
    return Realtime(fifo, priority, cpus, "; ".join(problems))

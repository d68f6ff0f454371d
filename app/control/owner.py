"""Who may move the robot now: the one owner of that question while a procedure runs.

A guided procedure (calibration, tuning) moves the robot from its own thread, in several
motions with gaps between them (the next pose, the step run then the chirp run). While it
runs, nothing else may move the robot, not even in those gaps: it ``claim``s the
``MotionOwner`` the controller holds (and ``bind``s its thread to the claim), and every
motion command of the controller (goals, jogs, moves, sources, gains and joint offsets;
the run manager's runs through them) asks ``permit()`` first, which refuses
(``MotionRefused``, HTTP 409) any caller but the claiming thread, naming the procedure and
how to stop it. E-stop, torque and reset never ask: they always work.

It is also the one place that says whether a new mover may start (``busy``): a claim, or
a mover that is not a claim but must not be overlapped by one, which registers how it
answers (``add_mover``: the run manager's test runs, which the loop plays and which a
procedure's thread may start under its own claim). A procedure starts only when ``busy``
says nothing, and ``claim`` refuses while it says something.

``release`` ends the claim; an abort releases it first and then stops the motion under
the same lock (see ``MotionOwner.release``), so a motion the procedure's thread had in
flight is queued before the stop, and none can follow it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from app.control.errors import MotionRefused


@dataclass(eq=False)
class Claim:
    """A procedure's hold on the robot: what it is (``what``, e.g. "calibration run
    cal-..."), and how the operator stops it (``stop``, e.g. "POST
    /api/calibration/cal-.../abort")."""

    what: str
    stop: str


class MotionOwner:
    """The current claim on the robot's motion, if any; safe from any thread.

    The thread a claim is ``bind``-ed to may move the robot while the claim holds, and
    never after it ends (an aborted procedure's thread is refused until it returns)."""

    def __init__(self) -> None:
        self._claim: Claim | None = None
        self._lock = threading.RLock()
        self._local = threading.local()  # .claim: the claim the calling thread works for
        self._movers: list[Callable[[], str | None]] = []  # add_mover's, in order
        self._on_claim: list[Callable[[Claim], object]] = []

    def add_mover(self, busy: Callable[[], str | None]) -> None:
        """A mover that holds no claim (the run manager) answers :meth:`busy` too, after
        the claim: ``busy()`` says why another mover may not start (e.g. "run ... is in
        progress; abort it first"), or None. It is asked under this owner's lock: it must
        not wait, nor call back into the owner."""
        with self._lock:
            self._movers.append(busy)

    def add_claim_listener(self, listener: Callable[[Claim], object]) -> None:
        """``listener(claim)`` as each claim is taken, before the claimer may move (e.g.
        to disarm another source of goals); it must not wait, nor call back into the
        owner."""
        with self._lock:
            self._on_claim.append(listener)

    def busy(self) -> str | None:
        """Why another mover (a procedure, a test run) may not start now, or None: the
        claim that holds the robot (named, with how to stop it), else the first mover of
        :meth:`add_mover` that is busy."""
        with self._lock:
            claim = self._claim
            if claim is not None:
                return f"{claim.what} is in progress; {claim.stop} to stop it"
            for mover in self._movers:
                if (why := mover()) is not None:
                    return why
            return None

    def claim(self, what: str, stop: str) -> Claim:
        """Take the robot for ``what``. Raises MotionRefused while another claim holds it
        or another mover is busy (:meth:`busy`'s answer)."""
        with self._lock:
            if (why := self.busy()) is not None:
                raise MotionRefused(why)
            self._claim = Claim(what, stop)
            for listener in self._on_claim:
                listener(self._claim)
            return self._claim

    def bind(self, claim: Claim) -> None:
        """The calling thread's motions are ``claim``'s from now on (call it first in the
        procedure's thread)."""
        self._local.claim = claim

    def release(self, claim: Claim, then: Callable[[], object] | None = None) -> None:
        """End ``claim`` (nothing if it has ended already), then call ``then()`` (e.g. queue
        a stop of the motion) before any other motion can be permitted."""
        with self._lock:
            if self._claim is claim:
                self._claim = None
            if then is not None:
                then()

    def check(self) -> None:
        """Raise MotionRefused where :meth:`permit` would (a check before slow planning)."""
        with self.permit():
            pass

    @contextmanager
    def permit(self) -> Iterator[None]:
        """Hold while a motion command is checked and queued. Raises MotionRefused when a
        claim holds the robot and the caller is not its thread, or the caller's own claim
        has ended (aborted)."""
        with self._lock:
            claim, mine = self._claim, getattr(self._local, "claim", None)
            if mine is not None and mine is not claim:
                raise MotionRefused(f"{mine.what} has ended (aborted)")
            if claim is not None and mine is not claim:
                raise MotionRefused(f"{claim.what} is in progress; {claim.stop} to stop it")
            yield

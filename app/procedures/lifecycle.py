"""One procedure's lifecycle on the robot: start, its thread, abort, the ending, close.

A ``ProcedureManager`` runs one run of its procedure at a time. ``_launch`` (called by
the procedure's ``start`` under ``_lock`` once ``_may_start`` let it) claims the
controller's ``MotionOwner`` (app/control/owner.py) for the run and starts its thread;
the thread ``bind``-s itself to the claim and runs the procedure's ``_steps``, which move
the arm through the controller and wait with ``_wait`` (it raises ``Stopped`` on an abort,
at shutdown, at an e-stop, a fault or torque off). The thread's ending is one step under
``_lock``: the claim released, ``result.json`` written, then the state published (done,
refused or failed with its error), so an abort finds the run either running (and stops
it) or ended. ``abort`` ends the run ``aborted`` at once: the claim released and the
motion stopped under the owner's lock (``_halt``), so nothing the thread had queued can
follow the stop; the thread moves nothing more and ends on its own.

One mover at a time: a run starts only when no other procedure holds the robot and no
test run is in progress (``MotionOwner.busy``, which the run manager answers too), and
while no run of its own kind is still running (``running``: its thread alive, even after
it let go of the robot to compute).

A procedure supplies: ``kind`` (names the claim, the thread and the messages), ``route``
(its API prefix: the abort route the claim names), ``running_states`` (states.py),
``_steps`` (what its thread does; the ending), ``failures`` (its own exceptions that fail
a run with their message), and where needed ``_ended_early`` (what a failed run keeps),
``_interrupt`` (work to kill at an abort or close) and ``_halt`` (how an abort stops the
motion). Its runs are ``ProcedureRun``-s: dataclasses with ``run_id``, ``folder``,
``state``, ``error``, ``aborted`` and a ``view()`` (the API's body, saved as result.json).
"""

from __future__ import annotations

import json
import logging
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Generic, TypeVar

from app.control.errors import GoalRejected, MotionRefused
from app.control.owner import Claim
from app.procedures.states import State

if TYPE_CHECKING:
    from app.control.controller import Controller
    from app.control.state import Snapshot

log = logging.getLogger(__name__)
Ending = tuple[str, str | None]  # the state a run ends in (done/refused/failed), its error
STOP_TIMEOUT_S = 5.0  # an abort's stop of the motion, once queued [s]
CLOSE_TIMEOUT_S = 5.0  # close waits this long for the run's thread [s]
ABORTED = "aborted by the operator"


class Stopped(Exception):
    """The run cannot go on (fault, e-stop, torque off, abort, shutdown, a timeout); the
    message says why (it becomes the failed run's ``error``)."""


def require_motion(snap: Snapshot, error: type[Exception] = MotionRefused) -> None:
    """Raise ``error`` (MotionRefused: HTTP 409) saying what to do first when the robot
    may not move in ``snap``: e-stop active, a fault, or torque off."""
    if snap.estopped:
        raise error("e-stop is active: POST /api/reset first")
    if snap.faults:
        raise error(f"fault: {snap.faults[0].reason}; POST /api/reset first")
    if not snap.torque:
        raise error('torque is off: POST /api/torque {"enabled": true} first')


class ProcedureRun:
    """What the lifecycle needs of a run; a procedure's run is a dataclass with these
    attributes (declared there, in its own field order) and its ``view``."""

    run_id: str
    folder: Path  # where its files go (result.json and the procedure's own)
    state: str
    error: str | None
    aborted: threading.Event  # set by abort (under the manager's lock)

    def advance(self, state: str, error: str | None = None) -> None:
        """The run's thread moves on to ``state`` (with ``error``, if given); an aborted
        run stays aborted."""
        if not self.aborted.is_set():
            self.state, self.error = state, error if error is not None else self.error

    def view(self) -> dict[str, Any]:
        """The API's body of the run (and its result.json)."""
        raise NotImplementedError


R = TypeVar("R", bound=ProcedureRun)


class ProcedureManager(Generic[R]):
    """Runs of one procedure on one controller, kept in memory by id; one at a time.

    Owns the lock, the runs, the run's thread, its claim on the robot, start (``_launch``),
    ``abort``, the ending, ``close``; the procedure's subclass supplies its steps."""

    kind: ClassVar[str]  # "calibration": "calibration run cal-...", "deltadash-calibration"
    prefix: ClassVar[str]  # the run ids' prefix: "cal" -> "cal-20260101-120000-abcd"
    route: ClassVar[str]  # the API's prefix: "/api/calibration"
    running_states: ClassVar[tuple[str, ...]]  # the states abort stops (states.py)
    failures: ClassVar[tuple[type[Exception], ...]] = ()  # its own errors: failed, said
    poll_s: ClassVar[float] = 0.005  # how often _wait looks again [s]

    def __init__(self, controller: Controller, folder: Path) -> None:
        self.controller, self.folder = controller, Path(folder)
        self._runs: dict[str, R] = {}
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()  # close: the thread's waits raise Stopped
        self._lock = threading.Lock()
        self._claim: Claim | None = None  # the robot, held by the run in progress

    def get(self, run_id: str) -> R | None:
        """The run ``run_id``, or None."""
        return self._runs.get(run_id)

    def running(self) -> bool:
        """A run's thread is working (moving the arm, or computing after letting go)."""
        thread = self._thread  # None once its run has ended (_hold)
        return thread is not None and thread.is_alive()

    def abort(self, run_id: str) -> R:
        """Stop the run ``run_id`` now: the motion stops (the robot holds where it is
        commanded, ``_halt``), work in flight is killed (``_interrupt``), the run ends
        ``aborted`` and the robot is free for other commands at once (its thread, if still
        computing, moves nothing more and ends on its own).

        Raises:
            KeyError: no run ``run_id`` (404).
            MotionRefused: the run is not running (done, failed, aborted...) (409).
        """
        run = self._runs[run_id]
        with self._lock:
            if run.state not in self.running_states or run.aborted.is_set():
                raise MotionRefused(
                    f"run {run_id} is {run.state}: only a running run can be aborted"
                )
            run.aborted.set()
            run.state, run.error = State.ABORTED, ABORTED
            claim = self._claim  # None once the run has let go of the robot
            self._interrupt()
            if claim is not None:
                self.controller.owner.release(claim, then=lambda: self._halt(run))
            self._save(run)  # under the lock: the thread's last save cannot land after it
        return run

    def close(self) -> None:
        """At shutdown: the run's waits raise Stopped, work in flight is killed; waits for
        its thread (at most ``CLOSE_TIMEOUT_S``)."""
        with self._lock:
            self._stop.set()
            self._interrupt()
        thread = self._thread
        if thread is not None:
            thread.join(timeout=CLOSE_TIMEOUT_S)

    # ---- for the procedure's start ----
    def _may_start(self) -> Snapshot:
        """Under ``_lock``: the snapshot now, if a run may start in it.

        Raises:
            MotionRefused: a run of this kind is in progress, another procedure holds the
                robot or a test run is in progress (named, with how to stop it), or the
                robot may not move (e-stop, fault, torque off) (409).
        """
        if self.running():
            raise MotionRefused(f"a {self.kind} run is in progress")
        if (other := self.controller.owner.busy()) is not None:
            raise MotionRefused(other)
        snap = self.controller.snapshot()
        require_motion(snap)
        return snap

    def _launch(self, make: Callable[[str, Path], R]) -> R:
        """Under ``_lock``, once the run may start: claim the robot for a new run id, make
        the run (``make(run_id, folder)``, its folder made), keep it and start its thread.
        Nothing keeps the robot held but a running thread: the claim is released if any
        of this fails.

        Raises:
            MotionRefused: another claim holds the robot (409).
        """
        run_id = f"{self.prefix}-" + time.strftime("%Y%m%d-%H%M%S") + "-" + uuid.uuid4().hex[:4]
        owner = self.controller.owner
        claim = owner.claim(f"{self.kind} run {run_id}", f"POST {self.route}/{run_id}/abort")
        try:
            folder = self.folder / run_id
            folder.mkdir(parents=True, exist_ok=True)
            run = make(run_id, folder)
            self._runs[run_id] = run
            self._stop.clear()
            self._claim = claim
            self._thread = threading.Thread(
                target=self._hold, args=(run, claim), name=f"deltadash-{self.kind}", daemon=True
            )
            self._thread.start()
        except BaseException:
            owner.release(claim)
            raise
        return run

    # ---- the run's thread ----
    def _hold(self, run: R, claim: Claim) -> None:
        """The thread: its motions are ``claim``'s; the robot is free again when it ends."""
        owner = self.controller.owner
        owner.bind(claim)
        ending: Ending = (State.FAILED, "internal error: the run's thread ended early")
        try:
            ending = self._execute(run)
        finally:
            # one step under the lock, so an abort finds the run either running (and stops
            # it) or ended: the robot freed, result.json written, then the state published;
            # a client that sees the run ended finds its files and the robot free, and may
            # start the next run at once
            with self._lock:
                if self._claim is claim:
                    self._claim = None
                owner.release(claim)
                try:
                    self._save(run, ending)
                except Exception:  # a full disk, a bug in the view: the run still ends
                    log.exception("%s run %s: result.json not written", self.kind, run.run_id)
                run.advance(*ending)
                if self._thread is threading.current_thread():
                    self._thread = None  # not running from here on (running())

    def _execute(self, run: R) -> Ending:
        """The procedure's steps; the state the run ends in, with its error: failed with
        the message of a Stopped, a refused motion or goal or one of ``failures``, failed
        saying so on any other exception (a bug ends the run, never the server)."""
        try:
            return self._steps(run)
        except (Stopped, GoalRejected, MotionRefused, *self.failures) as exc:
            self._ended_early(run)
            return State.FAILED, str(exc)
        except Exception as exc:
            log.exception("%s run %s failed", self.kind, run.run_id)
            self._ended_early(run)
            return State.FAILED, f"internal error: {exc!r}"

    def _steps(self, run: R) -> Ending:
        """What the run's thread does (the procedure's own): advances ``run`` through its
        running states; the state it ends in (done, refused) with its error. Raises
        Stopped, or another exception, to fail the run."""
        raise NotImplementedError

    def _ended_early(self, run: R) -> None:
        """A run that failed keeps what it can (the thread, before its ending is saved)."""

    def _interrupt(self) -> None:
        """Under ``_lock``, at an abort or close: kill work in flight that no motion stop
        ends (a worker process)."""

    def _halt(self, run: R) -> None:
        """At an abort, under the owner's lock, the claim released: stop the motion."""
        del run
        self._stop_motion()

    def _stop_motion(self) -> None:
        """The arm holds where it is commanded (returns once the loop has stopped it)."""
        self.controller.stop_any().result(timeout=STOP_TIMEOUT_S)

    def _let_go(self) -> None:
        """The run needs the robot no more (it only computes from here): its claim ends,
        so an abort then stops nothing the operator started since. The run stays running
        (``running``) until its thread ends."""
        with self._lock:
            claim, self._claim = self._claim, None
        if claim is not None:
            self.controller.owner.release(claim)

    def _save(self, run: R, ending: Ending | None = None) -> None:
        """The run's result.json: its ``view()`` as it is, or as it will be once it ends
        in ``ending`` (an aborted run stays aborted)."""
        body = run.view()
        if ending is not None and not run.aborted.is_set():
            body["state"], body["error"] = ending[0], ending[1] or body["error"]
        (run.folder / "result.json").write_text(json.dumps(body, indent=1))

    def _wait(
        self,
        run: R,
        what: str,
        until: Callable[[Snapshot], bool],
        timeout_s: float,
        met_first: bool = False,
    ) -> Snapshot:
        """Poll the controller's snapshot every ``poll_s`` until ``until(snap)``; that
        snapshot. ``until`` is asked once a look, after the checks (``met_first``: before
        them, so an event that has happened, e.g. a recorded run that ended, answers even
        if the robot stopped since).

        Raises:
            Stopped: the server is shutting down, the run was aborted, the robot may not
                move (e-stop, fault, torque off), or ``timeout_s`` [s] passed ("waiting for
                ``what``").
        """
        deadline = time.monotonic() + timeout_s
        while True:
            snap = self.controller.snapshot()
            if met_first and until(snap):
                return snap
            if self._stop.is_set():
                raise Stopped("the server is shutting down")
            if run.aborted.is_set():
                raise Stopped(ABORTED)
            require_motion(snap, Stopped)
            if not met_first and until(snap):
                return snap
            if time.monotonic() > deadline:
                raise Stopped(f"timed out after {timeout_s:g} s waiting for {what}")
            time.sleep(self.poll_s)

"""The procedures' one lifecycle (app/procedures/lifecycle.py) on a fake two-step procedure
and a fake controller: start, its running states, done; abort mid-step; a failing step;
one run at a time; close. No robot, no loop; the test waits on events, with deadlines."""

from __future__ import annotations

import json
import threading
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from app.control.errors import MotionRefused
from app.control.owner import MotionOwner
from app.procedures.lifecycle import Ending, ProcedureManager, ProcedureRun, Stopped
from app.procedures.states import State

DEADLINE_S = 10.0


class FakeController:
    """What the lifecycle uses of the controller: its owner, a snapshot, stop_any."""

    def __init__(self) -> None:
        self.owner = MotionOwner()
        self.estopped = False
        self.stops = 0

    def snapshot(self) -> Any:
        return SimpleNamespace(estopped=self.estopped, faults=(), torque=True)

    def stop_any(self) -> Future:
        self.stops += 1
        done: Future = Future()
        done.set_result(True)
        return done


class PlateMoved(Exception):
    """The fake procedure's own failure."""


@dataclass
class FakeRun(ProcedureRun):
    run_id: str
    folder: Path
    state: str = State.PLANNED
    error: str | None = None
    aborted: threading.Event = field(default_factory=threading.Event, repr=False)

    def view(self) -> dict[str, Any]:
        return {"run_id": self.run_id, "state": self.state, "error": self.error}


class FakeProcedure(ProcedureManager[FakeRun]):
    """Two steps (moving, then fitting), each waiting for the test to let it go on."""

    kind, prefix, route = "fake", "fake", "/api/fake"
    running_states = (State.PLANNED, State.MOVING, State.FITTING)
    failures = (PlateMoved,)
    poll_s = 0.001

    def __init__(self, controller: FakeController, folder: Path) -> None:
        super().__init__(controller, folder)  # type: ignore[arg-type]
        self.entered = [threading.Event(), threading.Event()]  # the thread is in step k
        self.go_on = [threading.Event(), threading.Event()]  # the test lets step k end
        self.fail_in_step: Exception | None = None  # raised in the second step
        self.kept: list[str] = []  # runs _ended_early was called for

    def start(self) -> FakeRun:
        with self._lock:
            self._may_start()
            return self._launch(lambda run_id, folder: FakeRun(run_id, folder))

    def _steps(self, run: FakeRun) -> Ending:
        for k, state in enumerate((State.MOVING, State.FITTING)):
            run.advance(state)
            self.entered[k].set()
            self._wait(run, f"step {k + 1}", lambda _, k=k: self.go_on[k].is_set(), DEADLINE_S)
            if k == 1 and self.fail_in_step is not None:
                raise self.fail_in_step
        return State.DONE, None

    def _ended_early(self, run: FakeRun) -> None:
        self.kept.append(run.run_id)


@pytest.fixture
def fake(tmp_path) -> tuple[FakeProcedure, FakeController]:
    controller = FakeController()
    manager = FakeProcedure(controller, tmp_path)
    yield manager, controller
    for gate in manager.go_on:
        gate.set()
    manager.close()


def _started(manager: FakeProcedure) -> tuple[FakeRun, threading.Thread]:
    run = manager.start()
    thread = manager._thread
    assert thread is not None
    return run, thread


def _ended(thread: threading.Thread) -> None:
    thread.join(DEADLINE_S)
    assert not thread.is_alive(), "the run's thread did not end"


def _saved(run: FakeRun) -> dict[str, Any]:
    return json.loads((run.folder / "result.json").read_text())


def test_a_run_goes_through_its_running_states_to_done_holding_the_robot(fake) -> None:
    manager, controller = fake
    run, thread = _started(manager)
    assert run.run_id.startswith("fake-") and manager.get(run.run_id) is run
    assert manager.entered[0].wait(DEADLINE_S)
    assert run.state == "moving" and manager.running()
    busy = controller.owner.busy() or ""
    assert f"fake run {run.run_id}" in busy and f"POST /api/fake/{run.run_id}/abort" in busy
    with pytest.raises(MotionRefused, match=f"fake run {run.run_id}"):
        controller.owner.check()  # no other thread moves the robot meanwhile
    manager.go_on[0].set()
    assert manager.entered[1].wait(DEADLINE_S)
    assert run.state == "fitting"
    manager.go_on[1].set()
    _ended(thread)
    assert (run.state, run.error) == ("done", None)
    assert _saved(run)["state"] == "done"
    assert controller.owner.busy() is None and not manager.running()
    assert manager.kept == [] and controller.stops == 0


def test_an_abort_mid_step_ends_the_run_aborted_and_frees_the_robot_at_once(fake) -> None:
    manager, controller = fake
    run, thread = _started(manager)
    assert manager.entered[0].wait(DEADLINE_S)
    assert manager.abort(run.run_id) is run
    assert (run.state, run.error) == ("aborted", "aborted by the operator")
    assert controller.owner.busy() is None  # free before the thread has even noticed
    assert controller.stops == 1  # the motion stopped (_halt)
    _ended(thread)  # its wait raised Stopped (result.json is read once it has written it)
    assert not manager.entered[1].is_set()  # it did not go on to the next step
    assert run.state == "aborted" and _saved(run)["state"] == "aborted"
    with pytest.raises(MotionRefused, match="is aborted: only a running run"):
        manager.abort(run.run_id)
    with pytest.raises(KeyError):
        manager.abort("fake-none")


@pytest.mark.parametrize(
    ("raised", "error"),
    [
        (PlateMoved("the plate moved"), "the plate moved"),
        (Stopped("timed out"), "timed out"),
        (ValueError("a bug"), "internal error: ValueError('a bug')"),
    ],
)
def test_a_failing_step_ends_the_run_failed_with_its_error(fake, raised, error) -> None:
    manager, controller = fake
    manager.fail_in_step = raised
    manager.go_on[0].set()
    manager.go_on[1].set()
    run, thread = _started(manager)
    _ended(thread)
    assert (run.state, run.error) == ("failed", error)
    assert (_saved(run)["state"], _saved(run)["error"]) == ("failed", error)
    assert manager.kept == [run.run_id]  # it kept what it could
    assert controller.owner.busy() is None and not manager.running()


def test_a_stop_of_the_robot_fails_the_step_waiting_on_it(fake) -> None:
    manager, controller = fake
    run, thread = _started(manager)
    assert manager.entered[0].wait(DEADLINE_S)
    controller.estopped = True
    _ended(thread)
    assert (run.state, run.error) == ("failed", "e-stop is active: POST /api/reset first")


def test_one_mover_at_a_time(fake) -> None:
    manager, controller = fake
    run, thread = _started(manager)
    assert manager.entered[0].wait(DEADLINE_S)
    with pytest.raises(MotionRefused, match="a fake run is in progress"):
        manager.start()
    manager.abort(run.run_id)  # the robot is free at once; the thread ends on its own
    _ended(thread)
    other = controller.owner.claim("tuning run t1", "POST /api/tuning/t1/abort")
    with pytest.raises(MotionRefused, match="tuning run t1 is in progress; POST /api/tuning/t1"):
        manager.start()
    controller.owner.release(other)
    running = {"run": "run r1 is in progress; abort it first"}
    controller.owner.add_mover(lambda: running["run"])  # the run manager's test run
    with pytest.raises(MotionRefused, match="^run r1 is in progress; abort it first$"):
        manager.start()
    with pytest.raises(MotionRefused, match="run r1"):
        controller.owner.claim("tuning run t2", "POST /api/tuning/t2/abort")
    running["run"] = None
    controller.estopped = True
    with pytest.raises(MotionRefused, match="e-stop is active"):
        manager.start()
    assert len(manager._runs) == 1  # nothing refused left a run (or a claim) behind
    assert controller.owner.busy() is None


def test_close_stops_the_running_thread(fake) -> None:
    manager, controller = fake
    run, thread = _started(manager)
    assert manager.entered[0].wait(DEADLINE_S)
    manager.close()
    assert not thread.is_alive()
    assert (run.state, run.error) == ("failed", "the server is shutting down")
    assert controller.owner.busy() is None and not manager.running()

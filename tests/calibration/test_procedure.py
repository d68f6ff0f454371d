"""What a calibration run refuses to apply (app/calibration/procedure.py), without a robot."""

from __future__ import annotations

import json
import math
import threading

import numpy as np
import pytest

from app.calibration.fit import fit, plan
from app.calibration.procedure import CalibrationManager, CalibrationRun
from app.control.errors import MotionRefused
from kinematics import THESIS_DELTA, PerLegRotaryDelta

NOMINAL = PerLegRotaryDelta.from_symmetric(THESIS_DELTA)


class NoController:
    """Fails the test if apply reaches the controller."""

    def __getattr__(self, name):
        raise AssertionError(f"apply used controller.{name} for a run it must refuse")


def _run(tmp_path, parameters: str, state: str) -> tuple[CalibrationManager, CalibrationRun]:
    chosen = plan(NOMINAL, 24, parameters)
    true = NOMINAL.with_values(joint_offsets_rad=(math.radians(2.0), 0.0, 0.0))
    y = true.fk(chosen.joints).points
    result = fit(NOMINAL, chosen.joints, y, len(chosen.holdout_joints), parameters)
    run = CalibrationRun("cal-x", parameters, 24, chosen, tmp_path, state=state, result=result)
    manager = CalibrationManager(NoController(), tmp_path)  # type: ignore[arg-type]
    manager._runs[run.run_id] = run
    return manager, run


@pytest.mark.parametrize(
    ("parameters", "state", "message"),
    [
        ("offsets", "refused", "refused"),
        ("offsets", "moving", "only a done run"),
        ("offsets", "failed", "only a done run"),
        ("offsets", "applied", "applied already"),
    ],
)
def test_apply_refuses_with_the_reason(tmp_path, parameters, state, message) -> None:
    manager, _ = _run(tmp_path, parameters, state)
    with pytest.raises(MotionRefused, match=message):
        manager.apply("cal-x", [])


class InUse:
    """A controller whose model or joint offsets are not those a run was fitted against;
    fails the test if apply changes anything on it."""

    def __init__(self, version: int, offsets_rad) -> None:
        from types import SimpleNamespace

        self.model = SimpleNamespace(version=version, origin="calibration cal-y")
        self.joint_offsets_rad = np.array(offsets_rad, dtype=float)

    def __getattr__(self, name):
        raise AssertionError(f"apply used controller.{name} for a run it must refuse")


@pytest.mark.parametrize("parameters", ["offsets", "geometry"])
@pytest.mark.parametrize(("version", "offsets_rad"), [(1, (0.0, 0.0, 0.0)), (0, (0.01, 0.0, 0.0))])
def test_apply_refuses_a_run_fitted_against_another_model(
    tmp_path, parameters, version, offsets_rad
) -> None:
    """A calibration applied since the run started (another geometry, or other joint
    offsets): the run's fit is relative to what was in use then, so it is not applied."""
    manager, run = _run(tmp_path, parameters, "done")
    manager.controller = InUse(version, offsets_rad)  # type: ignore[assignment]
    with pytest.raises(MotionRefused, match="calibrate again"):
        manager.apply("cal-x", [])
    assert run.state == "done"


def test_a_probe_runs_geometry_is_not_applied(tmp_path) -> None:
    """Touch heights leave combinations of the legs unpinned (docs/calibration.md): a
    probe run's geometry is refused, naming why."""
    manager, run = _run(tmp_path, "geometry", "done")
    run.source = "probe"
    with pytest.raises(MotionRefused, match="probe's touch heights cannot pin"):
        manager.apply("cal-x", [])


def test_the_view_has_the_contract_fields(tmp_path) -> None:
    _, run = _run(tmp_path, "geometry", "done")
    body = run.view()
    assert set(body["parameters"]) == {"joint_offsets_rad", "L_m", "l_m", "R_m", "r_m"}
    for key in ("state", "rmse_before_m", "rmse_after_m", "holdout_rmse_m", "condition_number"):
        assert body[key] is not None, key
    assert body["unobservable"] == [] and len(body["singular_values"]) == 18
    assert np.isclose(body["parameters"]["joint_offsets_rad"][0], math.radians(2.0), atol=1e-6)


class Owned:
    """A controller with only the robot's owner (what a run's thread uses as it ends)."""

    def __init__(self) -> None:
        from app.control.owner import MotionOwner

        self.owner = MotionOwner()


def _ending_run(tmp_path, monkeypatch, ending, save):
    """A manager whose run is "moving" with its claim held; its thread's work ends in
    `ending` at once and `save(manager, run)` stands in for writing result.json."""
    controller = Owned()
    manager = CalibrationManager(controller, tmp_path)  # type: ignore[arg-type]
    run = _run(tmp_path, "offsets", "moving")[1]
    manager._runs = {run.run_id: run}
    claim = controller.owner.claim(f"calibration run {run.run_id}", "abort")
    manager._claim = claim
    monkeypatch.setattr(CalibrationManager, "_execute", lambda self, r: ending)
    real_save = CalibrationManager._save

    def saving(self, r, ending=None):
        save(self, r)
        real_save(self, r, ending)

    monkeypatch.setattr(CalibrationManager, "_save", saving)
    return manager, run, claim


def test_a_run_says_it_ended_only_once_its_file_is_written_and_the_robot_free(
    tmp_path, monkeypatch
) -> None:
    """What a client polling the run sees: while result.json is being written the run is
    still running, and the robot is already free; after, the file and the state agree."""
    seen = []
    manager, run, claim = _ending_run(
        tmp_path,
        monkeypatch,
        ("failed", "measurement: the stream stopped"),
        lambda m, r: seen.append((r.state, m.controller.owner.busy(), m._claim)),
    )
    manager._hold(run, claim)
    assert seen == [("moving", None, None)], seen  # before: ("failed", "calibration run ...")
    assert (run.state, run.error) == ("failed", "measurement: the stream stopped")
    saved = json.loads((run.folder / "result.json").read_text())
    assert (saved["state"], saved["error"]) == (run.state, run.error)
    assert not manager.running()


class CountedLock:
    """A lock that says (``second``) when a second caller has asked for it."""

    def __init__(self) -> None:
        self._lock, self._asked, self.second = threading.Lock(), 0, threading.Event()

    def __enter__(self) -> None:
        self._asked += 1
        if self._asked >= 2:
            self.second.set()
        self._lock.acquire()

    def __exit__(self, *exc) -> None:
        self._lock.release()


def test_an_abort_while_a_run_ends_is_refused_and_stops_nothing(tmp_path, monkeypatch) -> None:
    """An abort that comes while the thread writes the run's end waits for it, then finds
    the run ended (409): it neither stops a motion someone started on the freed robot nor
    leaves result.json saying another state than the run."""
    writing, go_on = threading.Event(), threading.Event()

    def slow(manager, run) -> None:
        writing.set()
        assert go_on.wait(10.0)

    manager, run, claim = _ending_run(tmp_path, monkeypatch, ("done", None), slow)
    manager._stop_motion = lambda: pytest.fail("the abort stopped a motion")  # type: ignore[method-assign]
    manager._lock = CountedLock()  # type: ignore[assignment]
    thread = threading.Thread(target=manager._hold, args=(run, claim))
    thread.start()
    assert writing.wait(10.0)
    answer: dict = {}

    def abort() -> None:
        try:
            manager.abort(run.run_id)
            answer["aborted"] = True
        except MotionRefused as exc:
            answer["refused"] = str(exc)

    aborting = threading.Thread(target=abort)
    aborting.start()
    assert manager._lock.second.wait(10.0)  # the abort waits on the lock the ending holds
    go_on.set()
    thread.join(10.0)
    aborting.join(10.0)
    assert "refused" in answer and "is done" in answer["refused"], answer
    assert run.state == "done"
    assert json.loads((run.folder / "result.json").read_text())["state"] == "done"

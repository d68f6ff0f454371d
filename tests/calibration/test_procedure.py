"""What a calibration run refuses to apply (app/calibration/procedure.py), without a robot."""

from __future__ import annotations

import math

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

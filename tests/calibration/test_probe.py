"""Probe calibration (app/calibration/probe.py): touches of a flat plate, z only.

Laws: the simulated touches are where the true platform meets the plate; a robot wrong in
its joint offsets is recovered from touches of a plate of known height; with the plate's
height free, one plate cannot separate a common offset of the joints from the plate's
height (the SVD says so, and the direction is the one worked out by hand), two plates
can; a geometry fit names the combinations z-only data cannot pin and predicts the touch
heights anyway.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.calibration.fit import CalibrationError
from app.calibration.probe import (
    PINNED_SD,
    ProbeModel,
    probe_fit,
    probe_points,
    simulate_touches,
)
from kinematics import THESIS_DELTA, PerLegRotaryDelta

NOMINAL = PerLegRotaryDelta.from_symmetric(THESIS_DELTA)
OFFSETS = tuple(math.radians(d) for d in (3.0, -2.0, 2.5))
WRONG_OFFSETS = NOMINAL.with_values(joint_offsets_rad=OFFSETS)
WRONG_RODS = WRONG_OFFSETS.with_values(
    L=(0.1560, 0.1555, 0.1558), l=(0.2435, 0.2425, 0.2432), R=(0.0846, 0.0844, 0.0841)
)
NOISE_M = 2e-5
PLATE_M = -0.25
TOUCHES = 40
HOLDOUT = 10


def touches(robot, heights=(PLATE_M,), count=TOUCHES, noise_m=NOISE_M, seed=1, true_plate_dz=0.0):
    """Joints (N, 3) at the touches and the plate's *stated* heights (N,) [m], the
    held-out touches spread over every plate (every fourth)."""
    xy = np.vstack([probe_points(NOMINAL, z, count) for z in heights])
    stated = np.repeat(heights, count).astype(float)
    q = simulate_touches(robot, NOMINAL, xy, stated + true_plate_dz, noise_m, seed)
    order = np.r_[
        np.flatnonzero(np.arange(len(q)) % 4 != 3), np.flatnonzero(np.arange(len(q)) % 4 == 3)
    ]
    return q[order], stated[order], int(np.sum(np.arange(len(q)) % 4 == 3))


def offsets_error_deg(result) -> np.ndarray:
    return np.degrees(np.subtract(result.robot.joint_offsets_rad, OFFSETS))


@pytest.mark.slow
def test_a_touch_is_where_the_true_platform_meets_the_plate() -> None:
    xy = probe_points(NOMINAL, PLATE_M, 12)
    q = simulate_touches(WRONG_RODS, NOMINAL, xy, PLATE_M, noise_m=0.0)
    np.testing.assert_allclose(WRONG_RODS.fk(q).points[:, 2], PLATE_M, atol=1e-9)
    # the controller descended vertically: its own model puts the touch above the point
    np.testing.assert_allclose(NOMINAL.fk(q).points[:, :2], xy, atol=1e-9)
    # and on the wrong robot it believes the plate elsewhere (what the fit corrects)
    assert np.abs(NOMINAL.fk(q).points[:, 2] - PLATE_M).max() > 1e-3


@pytest.mark.slow
def test_offsets_are_recovered_from_a_plate_of_known_height() -> None:
    q, z, held = touches(WRONG_OFFSETS)
    result = probe_fit(NOMINAL, q, z, held, "offsets")
    assert np.all(np.abs(offsets_error_deg(result)) < 0.05), offsets_error_deg(result)
    assert result.observability.unobservable == ()
    assert result.holdout_before_m > 1e-3  # millimetres before
    assert result.holdout_rmse_m < 3 * NOISE_M and result.better
    assert result.rmse_after_m < 3 * NOISE_M


def _dz_dcommon(joints: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """d FK_z / d(common offset) at each touch (central difference), (N,) [m/rad]."""
    up, down = NOMINAL.fk(joints + step).points, NOMINAL.fk(joints - step).points
    return (up[:, 2] - down[:, 2]) / (2 * step)


@pytest.mark.slow
def test_one_plate_can_hardly_tell_a_common_offset_from_the_plate_height() -> None:
    """By hand: turning all three joints by d lowers each touch by -dFK_z/dtheta d, which
    varies only a little over the plate (less at the rim than the centre); a plate stated
    higher by the same amount hides almost all of it. So the weakest direction is (d, d,
    d, dz) with dz/d a mean of the per-touch derivatives: weak, but not zero, so whether
    the touches pin it depends on the probe's noise."""
    q, _, _ = touches(NOMINAL, noise_m=0.0)
    model = ProbeModel(NOMINAL, "offsets", plate_free=True)
    report = model.observability(model.initial, q, noise_m=NOISE_M)
    relative = report.singular_values / report.singular_values[0]
    assert 1e-3 < relative[-1] < 0.1, relative  # approximately, not exactly, the same
    assert relative[-2] > 0.3, relative  # only one such direction
    assert report.unobservable == ()  # a 20 um probe pins it (sd below 0.1 deg)
    noisy = model.observability(model.initial, q, noise_m=1e-4)
    assert set(noisy.unobservable) == {"offsets[0]", "offsets[1]", "offsets[2]", "plate_z"}
    assert len(noisy.combinations) == 1
    # the standard deviation the report states is the least-squares one: noise / s_k of the
    # Jacobian scaled by the typical errors (sd scales with the noise)
    stated = float(noisy.combinations[0].split("(sd ")[1].split()[0])
    assert PINNED_SD < stated < 5 * PINNED_SD
    # the direction in parameter units (undo the column scaling)
    jac = model.jacobian(model.initial, q)
    scale = np.linalg.norm(jac, axis=0)
    direction = np.linalg.svd(jac / scale)[2][-1] / scale
    offsets, dz = direction[:3], direction[3]
    assert np.all(np.sign(offsets) == np.sign(offsets[0]))  # a common turn of the joints
    assert np.ptp(offsets) < 0.3 * np.abs(offsets).mean()
    ratio = dz / offsets.mean()
    slopes = _dz_dcommon(q)
    assert slopes.min() <= ratio <= slopes.max(), (ratio, slopes.min(), slopes.max())


@pytest.mark.slow
def test_two_plates_pin_the_common_offset_and_the_plate_height() -> None:
    q, z, held = touches(WRONG_OFFSETS, heights=(-0.2, -0.3), true_plate_dz=5e-4)
    result = probe_fit(NOMINAL, q, z, held, "offsets", plate_free=True)
    assert result.observability.unobservable == ()
    assert np.all(np.abs(offsets_error_deg(result)) < 0.1), offsets_error_deg(result)
    assert abs(result.plate_error_m - 5e-4) < 1e-4, result.plate_error_m
    assert result.holdout_rmse_m < 3 * NOISE_M and result.better


@pytest.mark.slow
def test_one_plate_with_its_height_free_pins_the_differences_of_the_offsets() -> None:
    q, z, held = touches(WRONG_OFFSETS, true_plate_dz=5e-4)
    result = probe_fit(NOMINAL, q, z, held, "offsets", plate_free=True, noise_m=1e-4)
    assert "plate_z" in result.observability.unobservable  # at 0.1 mm of stated noise
    error = offsets_error_deg(result)
    assert np.ptp(error) < 0.1, error  # the differences, pinned; the common part is not
    assert result.holdout_rmse_m < 3 * NOISE_M and result.better


@pytest.mark.slow
def test_a_geometry_fit_names_what_heights_cannot_pin_and_predicts_the_touches() -> None:
    q, z, held = touches(WRONG_RODS, heights=(-0.2, -0.3))
    result = probe_fit(NOMINAL, q, z, held, "geometry")
    unobservable = set(result.observability.unobservable)
    assert {"l[0]", "l[1]", "l[2]"} <= unobservable, result.observability.combinations
    assert result.holdout_before_m > 1e-3
    assert result.holdout_rmse_m < 3 * NOISE_M and result.better
    # at new points of both plates, the fitted model's touch heights are the true ones
    fresh, stated, _ = touches(WRONG_RODS, heights=(-0.22, -0.28), count=15, noise_m=0.0)
    np.testing.assert_allclose(result.robot.fk(fresh).points[:, 2], stated, atol=1e-4)
    # and the parameters stay inside their physical bounds (no 234 mm rods)
    assert np.all(np.abs(np.subtract(result.robot.l, NOMINAL.l)) <= 5e-3 + 1e-12)


@pytest.mark.slow
def test_an_outlier_touch_does_not_drag_the_fit() -> None:
    q, z, held = touches(WRONG_OFFSETS)
    z = z.copy()
    z[0] += 3e-3  # one false trigger 3 mm off
    result = probe_fit(NOMINAL, q, z, held, "offsets")
    assert np.all(np.abs(offsets_error_deg(result)) < 0.1), offsets_error_deg(result)


@pytest.mark.slow
def test_bad_input_names_the_field() -> None:
    with pytest.raises(CalibrationError, match="plate_z_m"):
        probe_points(NOMINAL, 0.05, 10)  # above the base
    with pytest.raises(CalibrationError, match="touches"):
        probe_fit(NOMINAL, np.zeros((6, 3)), PLATE_M, 2)
    with pytest.raises(CalibrationError, match="parameters"):
        ProbeModel(NOMINAL, "frame")
    q, z, held = touches(NOMINAL, count=12)
    q[0, 1] = np.nan
    with pytest.raises(CalibrationError, match="finite"):
        probe_fit(NOMINAL, q, z, held)


@pytest.mark.slow
def test_one_plate_cannot_see_the_robot_scaled_with_the_plate_moved() -> None:
    """By hand: scaling every length of the robot (L, l and R - r) by 1 + s scales every
    FK point by 1 + s, so every touch of a plate at z0 moves by the same s z0: exactly what
    the plate's height does. Heights on one plate cannot see it; a second plate, at
    another height, moves by another s z, so two plates can."""
    q, _, _ = touches(NOMINAL, noise_m=0.0)
    model = ProbeModel(NOMINAL, "geometry", plate_free=True)
    jac = model.jacobian(model.initial, q)
    scale = np.linalg.norm(jac, axis=0)
    _, sigma, vt = np.linalg.svd(jac / scale)
    assert sigma[-1] < 1e-12 * sigma[0] < sigma[-2], sigma / sigma[0]  # exactly one
    found = vt[-1] / scale
    s = 1e-3
    rbar = np.subtract(NOMINAL.R, NOMINAL.r)
    by_hand = np.concatenate([np.zeros(3), s * np.array(NOMINAL.L), s * np.array(NOMINAL.l)])
    by_hand = np.concatenate([by_hand, s * rbar, [s * PLATE_M]])
    cosine = abs(found @ by_hand) / (np.linalg.norm(found) * np.linalg.norm(by_hand))
    assert cosine > 1 - 1e-9, cosine
    report = model.observability(model.initial, q)
    assert {"L[0]", "l[0]", "R[0]", "plate_z"} <= set(report.unobservable)
    two, _, _ = touches(NOMINAL, heights=(-0.2, -0.3), noise_m=0.0)
    sigma2 = np.linalg.svd(model.jacobian(model.initial, two) / scale, compute_uv=False)
    assert sigma2[-1] > 1e-5 * sigma2[0], sigma2 / sigma2[0]


@pytest.mark.slow  # many fits: seconds of CPU
def test_the_stated_standard_deviation_is_the_scatter_of_fits() -> None:
    """The report's sd of the weak direction (one plate, plate height free, 0.1 mm of
    noise) against the scatter of that direction over fits of 16 noise draws."""
    noise = 1e-4
    truth = WRONG_OFFSETS
    model = ProbeModel(NOMINAL, "offsets", plate_free=True)
    q0, z0, held = touches(truth, noise_m=0.0)
    report = model.observability(model.initial, q0[:-held], noise_m=noise)
    stated = float(report.combinations[0].split("(sd ")[1].split()[0])
    jac = model.jacobian(model.initial, q0[:-held]) * model.typical
    direction = np.linalg.svd(jac)[2][-1]
    true_x = np.concatenate([OFFSETS, [0.0]]) / model.typical
    seen = []
    for seed in range(16):
        q, z, held = touches(truth, noise_m=noise, seed=100 + seed)
        result = probe_fit(NOMINAL, q, z, held, "offsets", plate_free=True, noise_m=noise)
        x = np.concatenate([result.robot.joint_offsets_rad, [result.plate_error_m]])
        seen.append(float((x / model.typical - true_x) @ direction))
    scatter = float(np.sqrt(np.mean(np.square(seen))))
    assert 0.55 * stated < scatter < 1.6 * stated, (scatter, stated)


class _Idle:
    """A controller that may move (what ``start`` checks before planning)."""

    robot = THESIS_DELTA

    def __init__(self) -> None:
        from types import SimpleNamespace

        from app.control.owner import MotionOwner

        self.owner = MotionOwner()  # nobody holds the robot
        self.model = SimpleNamespace(robot=THESIS_DELTA, version=0)  # the config's
        self.joint_offsets_rad = np.zeros(3)

    def snapshot(self):
        from types import SimpleNamespace

        return SimpleNamespace(estopped=False, faults=(), torque=True)


def test_a_backend_without_a_probe_refuses_probe_runs_naming_the_source(tmp_path) -> None:
    from app.calibration.procedure import CalibrationManager

    manager = CalibrationManager(_Idle(), tmp_path)  # type: ignore[arg-type]
    with pytest.raises(CalibrationError, match="source: this backend has no probe"):
        manager.start(20, "offsets", source="probe", plate_z_m=PLATE_M)
    with pytest.raises(CalibrationError, match="source"):
        manager.start(20, "offsets", source="laser")
    assert not list(tmp_path.iterdir())  # nothing planned, no run folder

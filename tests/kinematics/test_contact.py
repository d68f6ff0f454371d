"""The tip's contact force from joint torques (kinematics/contact.py): the Jacobian against
finite differences of FK, virtual work, round trips through J^T, the covariance against
sampling, and the one-sample float path against the array functions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinematics import THESIS_DELTA, LinearDelta, NonFiniteError, RotaryDelta, ShapeError
from kinematics.contact import (
    _joint_to_tip_force_floats,
    _tip_force_covariance_floats,
    joint_to_tip_force,
    tip_force,
    tip_force_covariance,
)
from kinematics.differential import (
    _dexterity_floats,
    _jacobian_floats,
    _leg_frame_floats,
    dexterity,
    jacobian,
)
from kinematics.dynamics import THESIS_MASS, _inverse_dynamics_floats, inverse_dynamics_joints
from tests.support.strategies import BATCH_SHAPES

ROBOTS = (THESIS_DELTA, RotaryDelta(L=0.1, l=0.25, R=0.08, r=0.02))
MASS = THESIS_MASS.with_payload(0.1)


def _usable_joints(robot: RotaryDelta, rng: np.random.Generator, shape: tuple) -> np.ndarray:
    """Joints (shape, 3) away from singularities (dexterity > 0.1)."""
    q = rng.uniform(0.1, 1.2, shape + (3,))
    bad = ~(np.nan_to_num(robot.dexterity(q)) > 0.1)
    q[bad] = robot.ik([0.0, 0.0, -0.8 * robot.l]).joints  # the middle of the workspace
    return q


@pytest.mark.parametrize("robot", ROBOTS)
def test_the_jacobian_is_the_derivative_of_fk(robot):
    """The J the force goes through (differential.py) against central differences of FK."""
    q = _usable_joints(robot, np.random.default_rng(1), (6,))
    h = 1e-6
    numeric = np.stack(
        [(robot.fk(q + h * e).points - robot.fk(q - h * e).points) / (2 * h) for e in np.eye(3)],
        axis=-1,
    )
    np.testing.assert_allclose(jacobian(robot, q), numeric, rtol=1e-6, atol=1e-8)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), BATCH_SHAPES, st.sampled_from(ROBOTS))
def test_virtual_work(seed, shape, robot):
    """F . pd = (tau - tau_model) . qd with pd = J qd: the contact's power is the motors'
    excess power, for any torques and motion."""
    rng = np.random.default_rng(seed)
    q = _usable_joints(robot, rng, shape)
    qd, qdd = rng.normal(size=q.shape), 5 * rng.normal(size=q.shape)
    tau = rng.normal(scale=0.3, size=q.shape)
    gravity = rng.normal(scale=5.0, size=3)
    force = tip_force(robot, MASS, q, qd, qdd, tau, gravity)
    assert force.shape == shape + (3,)
    pd = robot.point_velocity(q, qd)
    excess = tau - inverse_dynamics_joints(robot, MASS, q, qd, qdd, gravity)
    np.testing.assert_allclose((force * pd).sum(-1), (excess * qd).sum(-1), rtol=1e-8, atol=1e-10)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), BATCH_SHAPES)
def test_round_trip_through_the_jacobian_transpose(seed, shape):
    """tau = tau_model + J^T F for a chosen F gives F back (J^T from np.linalg, not the
    adjugate form the module uses)."""
    rng = np.random.default_rng(seed)
    q = _usable_joints(THESIS_DELTA, rng, shape)
    qd, qdd = rng.normal(size=q.shape), 5 * rng.normal(size=q.shape)
    chosen = rng.normal(scale=3.0, size=q.shape)
    jac = jacobian(THESIS_DELTA, q)
    model = inverse_dynamics_joints(THESIS_DELTA, MASS, q, qd, qdd, (0.0, 2.0, -9.5))
    tau = model + np.einsum("...ji,...j->...i", jac, chosen)
    got = tip_force(THESIS_DELTA, MASS, q, qd, qdd, tau, (0.0, 2.0, -9.5))
    np.testing.assert_allclose(got, chosen, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(
        joint_to_tip_force(THESIS_DELTA, q, tau - model), chosen, rtol=1e-7, atol=1e-9
    )


def test_the_model_torques_alone_are_no_force_and_a_weight_is_its_weight():
    """At rest, the torques that hold the arm read as zero force; with a mass m hanging on
    the tip (the model's platform heavier by m) the tip holds it up: it applies +m |g| z
    on the mass (pressing down on a plate would be -z)."""
    q = THESIS_DELTA.ik([0.02, -0.03, -0.25]).joints
    zero = np.zeros(3)
    holding = inverse_dynamics_joints(THESIS_DELTA, MASS, q, zero, zero)
    np.testing.assert_allclose(
        tip_force(THESIS_DELTA, MASS, q, zero, zero, holding), zero, atol=1e-12
    )
    loaded = inverse_dynamics_joints(THESIS_DELTA, MASS.with_payload(0.2), q, zero, zero)
    np.testing.assert_allclose(
        tip_force(THESIS_DELTA, MASS, q, zero, zero, loaded), [0.0, 0.0, 0.2 * 9.81], atol=1e-12
    )


def test_covariance_matches_sampling():
    """Cov F against the scatter of F over sampled torque errors (200 000 draws)."""
    rng = np.random.default_rng(7)
    q = THESIS_DELTA.ik([0.05, 0.02, -0.22]).joints
    s = np.array([0.02, 0.05, 0.01])
    zero = np.zeros(3)
    model = inverse_dynamics_joints(THESIS_DELTA, MASS, q, zero, zero)
    taus = model + rng.normal(size=(200_000, 3)) * s
    forces = tip_force(THESIS_DELTA, MASS, q, zero, zero, taus)
    sampled = np.cov(forces.T)
    cov = tip_force_covariance(THESIS_DELTA, q, s)
    scale = np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    np.testing.assert_allclose(sampled / scale, cov / scale, atol=0.01)
    # batched, and by hand J^-T S^2 J^-1
    inv = np.linalg.inv(jacobian(THESIS_DELTA, q))
    np.testing.assert_allclose(cov, inv.T @ np.diag(s**2) @ inv, rtol=1e-9)
    batch = tip_force_covariance(THESIS_DELTA, np.stack([q, q]), s)
    assert batch.shape == (2, 3, 3)
    np.testing.assert_allclose(batch[1], cov, rtol=1e-12)


def test_out_of_reach_and_nan_rows_are_nan():
    zero = np.zeros((3, 3))
    q = np.array(
        [
            THESIS_DELTA.ik([0.0, 0.0, -0.25]).joints,
            [3.0, 0.0, 0.0],  # leg 1 folded back over the base: the spheres miss, no FK
            THESIS_DELTA.ik([0.0, 0.0, -0.25]).joints,
        ]
    )
    tau = np.array([[0.1, 0.1, 0.1], [0.1, 0.1, 0.1], [np.nan, 0.1, 0.1]])
    force = tip_force(THESIS_DELTA, MASS, q, zero, zero, tau)
    assert np.isfinite(force[0]).all()
    assert np.isnan(force[1]).all() and np.isnan(force[2]).all()
    cov = tip_force_covariance(THESIS_DELTA, q, [0.01, 0.01, 0.01])
    assert np.isfinite(cov[0]).all() and np.isnan(cov[1]).all()


def test_bad_inputs_are_named():
    q = THESIS_DELTA.ik([0.0, 0.0, -0.25]).joints
    zero = np.zeros(3)
    with pytest.raises(ShapeError, match="torques_nm"):
        tip_force(THESIS_DELTA, MASS, q, zero, zero, [1.0, 2.0])
    with pytest.raises(NonFiniteError, match="torque_std_nm"):
        tip_force_covariance(THESIS_DELTA, q, [0.01, -0.01, 0.01])
    with pytest.raises(NonFiniteError, match="torque_std_nm"):
        tip_force_covariance(THESIS_DELTA, q, [0.01, np.nan, 0.01])
    with pytest.raises(TypeError, match="RotaryDelta"):
        tip_force(LinearDelta(l=0.3, R=0.15, r=0.03), MASS, q, zero, zero, zero)
    with pytest.raises(TypeError, match="RotaryDelta"):
        tip_force_covariance(LinearDelta(l=0.3, R=0.15, r=0.03), q, zero)


def test_one_sample_in_floats_is_the_array_path():
    """The control tick's float path (differential._leg_frame_floats and the helpers on
    it, app/control/force.py) gives the array functions' answers to 1e-12 of each result's
    size, over 300 seeded states per robot with joints over and past the workspace; near a
    singularity both lose digits alike (tolerance x 0.05 / dexterity below 0.05). It
    declines (None) exactly where FK fails."""
    rng = np.random.default_rng(33)
    declined = compared = near_singular = 0
    for robot in ROBOTS:
        q = rng.uniform(-2.5, 3.1, (300, 3))
        qd, qdd = rng.uniform(-3.0, 3.0, q.shape), rng.uniform(-20.0, 20.0, q.shape)
        gravity = 9.81 * rng.normal(size=q.shape)
        tau, std = rng.normal(scale=0.5, size=q.shape), rng.uniform(0.0, 0.1, q.shape)
        dex, jac = dexterity(robot, q), jacobian(robot, q)
        model = inverse_dynamics_joints(robot, MASS, q, qd, qdd, gravity)
        force, cov = joint_to_tip_force(robot, q, tau), tip_force_covariance(robot, q, std)
        fk_ok = robot.fk(q).ok
        for k in range(len(q)):
            q_k, qd_k, qdd_k, g_k, tau_k, std_k = (
                tuple(a[k].tolist()) for a in (q, qd, qdd, gravity, tau, std)
            )
            frame = _leg_frame_floats(robot, q_k)
            assert (frame is None) == (not fk_ok[k])
            if frame is None:
                declined += 1
                continue
            compared += 1
            near_singular += bool(dex[k] < 0.05)
            rtol = 1e-12 * max(1.0, 0.05 / dex[k])
            for fast, batch in (
                (_jacobian_floats(frame), jac[k]),
                (_dexterity_floats(_jacobian_floats(frame)), dex[k]),
                (_inverse_dynamics_floats(MASS, frame, qd_k, qdd_k, g_k), model[k]),
                (_joint_to_tip_force_floats(frame, tau_k), force[k]),
                (_tip_force_covariance_floats(frame, std_k), cov[k]),
            ):
                size = np.abs(batch).max()
                np.testing.assert_allclose(fast, batch, rtol=rtol, atol=rtol * size)
    assert declined >= 20 and near_singular >= 20 and compared >= 400, (declined, near_singular)

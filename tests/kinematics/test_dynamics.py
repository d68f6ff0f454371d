"""Inverse dynamics (kinematics/dynamics.py): work-energy law, virtual work, hand cases."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import simpson

from kinematics import THESIS_DELTA, InvalidGeometryError, RotaryDelta
from kinematics.dynamics import (
    THESIS_MASS,
    MassModel,
    energy,
    inverse_dynamics,
    inverse_dynamics_joints,
    joint_motion,
)
from tests.support.strategies import BATCH_SHAPES

G0 = 9.81


@st.composite
def mass_models(draw) -> MassModel:
    return MassModel(
        platform_kg=draw(st.floats(0.01, 1.0)),
        upper_kg=draw(st.floats(0.0, 0.2)),
        upper_inertia_kgm2=draw(st.floats(0.0, 0.02)),
        lower_kg=draw(st.floats(0.0, 0.1)),
    )


@st.composite
def gravities(draw) -> np.ndarray:
    """Any direction (a drone may tilt past vertical), magnitude 0-2 g."""
    direction = np.array(draw(st.tuples(*[st.floats(-1, 1)] * 3)))
    norm = np.linalg.norm(direction)
    if norm < 1e-3:
        direction, norm = np.array([0.0, 0.0, -1.0]), 1.0
    return direction / norm * draw(st.floats(0.0, 2.0 * G0))


def _trajectory(seed: int, centre: np.ndarray, amplitude: float, t: np.ndarray):
    """P(t) = centre + sum of three sines per axis, with exact derivatives."""
    rng = np.random.default_rng(seed)
    a = amplitude * rng.uniform(-1, 1, (3, 3)) / 3.0  # (harmonic, axis)
    w = rng.uniform(1.0, 12.0, (3, 3))  # rad/s
    phase = rng.uniform(0, 2 * np.pi, (3, 3))
    arg = w * t[:, None, None] + phase
    p = centre + (a * np.sin(arg)).sum(1)
    pd = (a * w * np.cos(arg)).sum(1)
    pdd = (-a * w**2 * np.sin(arg)).sum(1)
    return p, pd, pdd


@pytest.mark.slow
@settings(max_examples=50)  # each example integrates a 2001-sample trajectory
@given(mass_models(), gravities(), st.integers(0, 2**32 - 1), st.sampled_from([0, 1]))
def test_work_of_the_torques_is_the_change_of_energy(mass, gravity, seed, which):
    """Along a smooth motion, the integral of tau . qd dt equals Delta(K + U)."""
    robot = THESIS_DELTA if which == 0 else RotaryDelta(L=0.1, l=0.25, R=0.08, r=0.02)
    centre = robot.fk([0.6, 0.6, 0.6]).points
    t = np.linspace(0.0, 1.0, 2001)  # Simpson's error here ~1e-11 of the work
    p, pd, pdd = _trajectory(seed, centre, 0.06, t)
    q, qd, _ = joint_motion(robot, p, pd, pdd)
    if not (np.nan_to_num(robot.dexterity(q)) > 0.05).all():
        return  # too near a singularity for this trajectory to be a fair test
    torque = inverse_dynamics(robot, mass, p, pd, pdd, gravity)
    power = (torque * qd).sum(-1)
    work = simpson(power, x=t)
    e = energy(robot, mass, q, qd, gravity)
    total = e.kinetic + e.potential
    scale = simpson(np.abs(power), x=t) + 1e-12
    assert abs(work - (total[-1] - total[0])) <= 1e-7 * scale


def test_the_energy_law_notices_a_wrong_model():
    """The same check with the lower link's mass misstated in the energy fails clearly."""
    t = np.linspace(0.0, 1.0, 4001)
    p, pd, pdd = _trajectory(3, np.array([0.0, 0.0, -0.25]), 0.06, t)
    q, qd, _ = joint_motion(THESIS_DELTA, p, pd, pdd)
    mass = THESIS_MASS.with_payload(0.2)
    wrong = MassModel(mass.platform_kg, mass.upper_kg, mass.upper_inertia_kgm2, 2 * mass.lower_kg)
    power = (inverse_dynamics(THESIS_DELTA, mass, p, pd, pdd) * qd).sum(-1)
    e = energy(THESIS_DELTA, wrong, q, qd)
    total = e.kinetic + e.potential
    assert abs(simpson(power, x=t) - (total[-1] - total[0])) > 1e-3 * simpson(np.abs(power), x=t)


@pytest.mark.parametrize("z", [-0.12, -0.2, -0.3, -0.36])
def test_static_hand_case_on_the_axis(z):
    """Platform on the z axis, gravity -z: three equal torques, derived by hand.

    Leg 1 keeps (Rbar + L cos t)^2 + (z + L sin t)^2 = l^2; turning all three joints by
    the same angle keeps P on the axis, so dz/dt_all = (Rbar + L c) L s / (z + L s) - L c
    and by symmetry dz/dtheta_i = dz/dt_all / 3. Virtual work with
    U = (m_P + 3 m_L / 2) g z - sum (m_U + m_L)/2 g L sin(theta_i) gives tau_i = dU/dtheta_i.
    """
    robot, mass = THESIS_DELTA, THESIS_MASS.with_payload(0.2)
    L, Rbar = robot.L, robot.Rbar
    theta = float(robot.ik([0.0, 0.0, z]).joints[0])
    s, c = np.sin(theta), np.cos(theta)
    dz_all = (Rbar + L * c) * L * s / (z + L * s) - L * c
    carried = mass.platform_kg + 1.5 * mass.lower_kg
    expected = carried * G0 * dz_all / 3 - 0.5 * (mass.upper_kg + mass.lower_kg) * G0 * L * c
    torque = inverse_dynamics(robot, mass, [0.0, 0.0, z], np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(torque, np.full(3, expected), rtol=1e-9)
    assert expected < 0  # holding the load up is a torque towards negative theta


@pytest.mark.slow
@given(gravities(), st.integers(0, 2**32 - 1), BATCH_SHAPES)
def test_static_torques_are_virtual_work(gravity, seed, shape):
    """At rest, tau = -J^T (m_P + 3 m_L/2) g - (m_U + m_L)/2 g . dC_i/dtheta_i."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(0.1, 1.2, shape + (3,))
    robot, mass = THESIS_DELTA, THESIS_MASS.with_payload(0.2)
    p = robot.fk(q).points
    zero = np.zeros_like(p)
    usable = np.nan_to_num(robot.dexterity(q)) > 0.05
    torque = inverse_dynamics(robot, mass, p, zero, zero, gravity)
    jac = robot.jacobian(q)
    carried = mass.platform_kg + 1.5 * mass.lower_kg
    knee_rate = -robot.L * np.stack(
        [
            np.cos(a) * np.sin(q[..., i]) * gravity[0]
            + np.sin(a) * np.sin(q[..., i]) * gravity[1]
            + np.cos(q[..., i]) * gravity[2]
            for i, a in enumerate(np.radians([0, 120, 240]))
        ],
        -1,
    )  # g . dC_i/dtheta_i (eq. 3.96 in the base frame)
    expected = -np.einsum("...ji,j->...i", jac, carried * gravity)
    expected -= 0.5 * (mass.upper_kg + mass.lower_kg) * knee_rate
    np.testing.assert_allclose(torque[usable], expected[usable], atol=1e-9)


@pytest.mark.slow
@given(st.integers(0, 2**32 - 1))
def test_platform_only_robot_obeys_newton(seed):
    """Massless links: tau = J^T m_P (a - g) + I qdd (d'Alembert through the Jacobian)."""
    rng = np.random.default_rng(seed)
    mass = MassModel(0.3, 0.0, rng.uniform(0, 0.01), 0.0)
    p = np.array([0.0, 0.0, -0.25]) + rng.uniform(-0.05, 0.05, (8, 3))
    pd, pdd = rng.normal(size=(8, 3)), 4 * rng.normal(size=(8, 3))
    gravity = rng.normal(size=3) * 5
    q, _, qdd = joint_motion(THESIS_DELTA, p, pd, pdd)
    jac = THESIS_DELTA.jacobian(q)
    expected = np.einsum("...ji,...j->...i", jac, mass.platform_kg * (pdd - gravity))
    expected += mass.upper_inertia_kgm2 * qdd
    got = inverse_dynamics(THESIS_DELTA, mass, p, pd, pdd, gravity)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)


@pytest.mark.slow
@given(st.integers(0, 2**32 - 1), BATCH_SHAPES)
def test_joint_space_entry_agrees(seed, shape):
    rng = np.random.default_rng(seed)
    p = np.array([0.0, 0.0, -0.25]) + rng.uniform(-0.06, 0.06, shape + (3,))
    pd, pdd = rng.normal(size=shape + (3,)), rng.normal(size=shape + (3,))
    mass = THESIS_MASS.with_payload(0.1)
    motion = joint_motion(THESIS_DELTA, p, pd, pdd)
    by_platform = inverse_dynamics(THESIS_DELTA, mass, p, pd, pdd, (1.0, 2.0, -9.0))
    by_joints = inverse_dynamics_joints(THESIS_DELTA, mass, *motion, gravity=(1.0, 2.0, -9.0))
    assert by_platform.shape == shape + (3,)
    np.testing.assert_allclose(by_joints, by_platform, rtol=1e-8, atol=1e-10)


def test_unreachable_points_give_nan_not_errors():
    torque = inverse_dynamics(
        THESIS_DELTA, THESIS_MASS, [[0, 0, -0.25], [1, 0, 0]], 0.0 * np.ones(3), np.zeros(3)
    )
    assert np.isfinite(torque[0]).all() and np.isnan(torque[1]).all()


@pytest.mark.parametrize(
    "fields",
    [
        (0.0, 0.1, 0.1, 0.1),
        (0.1, -0.1, 0.1, 0.1),
        (0.1, 0.1, float("nan"), 0.1),
        (0.1, 0.1, 0.1, "1"),
    ],
)
def test_mass_model_is_validated(fields):
    with pytest.raises(InvalidGeometryError):
        MassModel(*fields)


def test_thesis_mass_model_numbers():
    """Ch. 4.2: 25 g platform, 29 g upper link, 2 x 10.5 g lower rods per leg."""
    assert THESIS_MASS.platform_kg == pytest.approx(0.025)
    assert THESIS_MASS.lower_kg == pytest.approx(0.021)
    assert THESIS_MASS.with_payload(0.2).platform_kg == pytest.approx(0.225)
    assert 2e-3 < THESIS_MASS.upper_inertia_kgm2 < 2e-2  # rotor through 212.6:1 dominates

"""The contact force estimate (app/control/force.py): by hand from model torques, its error
budget, refusals with reasons, and against forces applied to the twin's platform."""

from __future__ import annotations

import math

import numpy as np
import pytest

import app.control.force
from app.control.force import (
    GEARBOX_FRICTION_NM,
    TORQUE_CONSTANT_NM_A,
    ForceErrorBudget,
    ForceEstimate,
    ForceEstimator,
    force_estimator,
)
from hardware.bus import JointState
from hardware.dynamixel.control_table import AMPERE_PER_CURRENT_UNIT
from kinematics import THESIS_DELTA, LinearDelta, RotaryDelta
from kinematics.contact import joint_to_tip_force, tip_force_covariance
from kinematics.differential import dexterity
from kinematics.dynamics import THESIS_MASS, inverse_dynamics_joints, joint_motion

POINTS = (
    (0.0, 0.0, -0.24),
    (0.06, 0.04, -0.20),
    (-0.05, 0.06, -0.28),
    (0.04, -0.07, -0.26),
    (0.0, 0.0, -0.31),
    (-0.08, -0.03, -0.22),
)
FORCES = ((0.0, 0.0, -2.0), (1.5, 0.0, 0.0), (0.0, -1.5, -1.0))
ZERO = np.zeros(3)


def _state(q, qd, current_a, **kw) -> JointState:
    n = len(q)
    return JointState(
        position_rad=np.asarray(q, dtype=float),
        velocity_rad_s=np.asarray(qd, dtype=float),
        current_a=np.asarray(current_a, dtype=float),
        voltage_v=np.full(n, 12.0),
        temperature_c=np.full(n, 30.0),
        pwm=np.zeros(n),
        moving=np.zeros(n, dtype=bool),
        hardware_errors=kw.pop("hardware_errors", ((),) * n),
        stamp_s=0.0,
        **kw,
    )


def _currents(q, qd, qdd, force, gravity=(0.0, 0.0, -9.81), mass=THESIS_MASS) -> np.ndarray:
    """The currents [A] that hold the model's motion plus a tip force (eq. 1 of
    kinematics/contact.py), without friction."""
    model = inverse_dynamics_joints(THESIS_DELTA, mass, q, qd, qdd, gravity)
    return (model + THESIS_DELTA.jacobian(q).T @ np.asarray(force)) / TORQUE_CONSTANT_NM_A


def test_one_source_for_the_servos_constants():
    """Kt and friction are the twin's servo model's (hardware/sim/xm430.py), the current's
    unit the control table's: the estimate reads the twin with the twin's own constants."""
    from hardware.sim.xm430 import XM430_W210

    assert XM430_W210.torque_constant_nm_a == TORQUE_CONSTANT_NM_A
    assert pytest.approx(3.0 / 2.3) == TORQUE_CONSTANT_NM_A
    assert XM430_W210.coulomb_friction_nm == GEARBOX_FRICTION_NM
    assert ForceErrorBudget().current_quantum_a == AMPERE_PER_CURRENT_UNIT == 2.69e-3


@pytest.mark.parametrize("point", POINTS[:3])
@pytest.mark.parametrize("force", FORCES)
def test_the_force_in_the_currents_comes_back(point, force):
    q = THESIS_DELTA.ik(np.array(point)).joints
    got = ForceEstimator(THESIS_DELTA).estimate(_state(q, ZERO, _currents(q, ZERO, ZERO, force)))
    assert got.valid and got.reason is None
    np.testing.assert_allclose(got.force_n, force, atol=1e-9)
    np.testing.assert_allclose(got.std_n, np.sqrt(np.diag(got.covariance_n2)), rtol=1e-12)


def test_error_budget_by_hand_at_rest():
    """Each joint's sigma^2 = (0.1 tau)^2 + (Kt q / sqrt 12)^2 + f^2 + (0.1 tau_model)^2, and
    the force's covariance J^-T diag(sigma^2) J^-1."""
    q = THESIS_DELTA.ik(np.array([0.03, 0.02, -0.25])).joints
    current = _currents(q, ZERO, ZERO, (0.0, 0.0, -2.0))
    est = ForceEstimator(THESIS_DELTA)
    got = est.estimate(_state(q, ZERO, current))
    tau = TORQUE_CONSTANT_NM_A * current
    model = inverse_dynamics_joints(THESIS_DELTA, THESIS_MASS, q, ZERO, ZERO)
    quantum = TORQUE_CONSTANT_NM_A * 2.69e-3 / math.sqrt(12.0)
    sigma = np.sqrt((0.1 * tau) ** 2 + quantum**2 + 0.02**2 + (0.1 * model) ** 2)
    inverse = np.linalg.inv(THESIS_DELTA.jacobian(q))
    np.testing.assert_allclose(got.covariance_n2, inverse.T @ np.diag(sigma**2) @ inverse)
    # a budget of nothing but friction: std is J^-T's row norms times 0.02
    bare = ForceErrorBudget(kt_rel_std=0, current_quantum_a=0, mass_rel_std=0)
    only_friction = ForceEstimator(THESIS_DELTA, budget=bare).estimate(_state(q, ZERO, current))
    np.testing.assert_allclose(only_friction.std_n, 0.02 * np.linalg.norm(inverse.T, axis=1))


def test_tilted_gravity_and_a_payload_are_the_models():
    """Currents that hold the arm under a tilted gravity read zero with that gravity; read
    with level gravity they are a spurious force. The loop's payload is part of the model."""
    q = THESIS_DELTA.ik(np.array([0.02, -0.04, -0.23])).joints
    tilted = 9.81 * np.array([np.sin(0.3), 0.0, -np.cos(0.3)])
    current = _currents(q, ZERO, ZERO, ZERO, gravity=tilted)
    est = ForceEstimator(THESIS_DELTA)
    np.testing.assert_allclose(
        est.estimate(_state(q, ZERO, current), tilted).force_n, ZERO, atol=1e-9
    )
    assert np.linalg.norm(est.estimate(_state(q, ZERO, current)).force_n) > 0.05
    carried = _currents(q, ZERO, ZERO, ZERO, mass=THESIS_MASS.with_payload(0.1).with_wrist())
    loop = force_estimator(THESIS_DELTA, payload_kg=0.1, wrist=True)
    np.testing.assert_allclose(loop.estimate(_state(q, ZERO, carried)).force_n, ZERO, atol=1e-9)
    # the same currents against the bare model: the payload and wrist hang on the tip
    bare = est.estimate(_state(q, ZERO, carried)).force_n
    assert bare[2] == pytest.approx((0.1 + 0.082 + 0.020) * 9.81, rel=1e-6)


def test_acceleration_given_or_taken_as_zero():
    """While accelerating, the motors' inertial torque reads as a force unless qdd is given;
    friction opposing the motion is compensated."""
    p, pd, pdd = (
        np.array([0.0, 0.02, -0.25]),
        np.array([0.05, -0.1, 0.2]),
        np.array([0.0, 0.0, 3.0]),
    )
    q, qd, qdd = joint_motion(THESIS_DELTA, p, pd, pdd)
    assert (np.abs(qd) > 0.05).all()
    current = _currents(q, qd, qdd, ZERO) + 0.02 * np.sign(qd) / TORQUE_CONSTANT_NM_A
    est = ForceEstimator(THESIS_DELTA)
    given = est.estimate(_state(q, qd, current), qdd=qdd)
    np.testing.assert_allclose(given.force_n, ZERO, atol=1e-9)
    assumed = est.estimate(_state(q, qd, current))
    assert np.linalg.norm(assumed.force_n) > 0.1  # ~ J^-T I qdd: the rotor's inertia
    # moving, friction's sign is known: its part of the budget shrinks, the ripple enters
    rest = est.estimate(_state(q, ZERO, _currents(q, ZERO, ZERO, ZERO)))
    assert given.valid and rest.valid


def test_a_wrist_read_uses_the_legs():
    q = THESIS_DELTA.ik(np.array([0.0, 0.0, -0.25])).joints
    current = _currents(q, ZERO, ZERO, (0.5, 0.0, -1.0), mass=THESIS_MASS.with_wrist())
    state = _state(np.append(q, 0.3), np.zeros(4), np.append(current, 0.4))
    got = force_estimator(THESIS_DELTA, wrist=True).estimate(state)
    np.testing.assert_allclose(got.force_n, (0.5, 0.0, -1.0), atol=1e-9)


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"current": [0.1, math.nan, 0.1]}, "current of joint 2 not read"),
        ({"q": [0.5, 0.5, math.nan]}, "position or velocity of joint 3"),
        ({"torque_enabled": (True, False, True)}, "torque off on joint 2"),
        ({"hardware_errors": ((), (), ("overload",))}, "joint 3 in a hardware fault"),
        ({"q": [3.0, 0.0, 0.0]}, "out of the model's reach"),
        ({"q": [1.5, 1.5, 1.5], "min_dexterity": 0.5}, "dexterity 0.172 below 0.5"),
    ],
)
def test_refusals_say_why(change, reason):
    q = change.pop("q", THESIS_DELTA.ik(np.array([0.0, 0.0, -0.25])).joints)
    current = change.pop("current", [0.1, 0.1, 0.1])
    est = ForceEstimator(THESIS_DELTA, min_dexterity=change.pop("min_dexterity", 0.05))
    got = est.estimate(_state(q, ZERO, current, **change))
    assert not got.valid and reason in (got.reason or "")
    assert np.isnan(got.force_n).all() and np.isnan(got.std_n).all()


def test_bad_arguments_are_named():
    q = THESIS_DELTA.ik(np.array([0.0, 0.0, -0.25])).joints
    state = _state(q, ZERO, [0.1, 0.1, 0.1])
    est = ForceEstimator(THESIS_DELTA)
    with pytest.raises(ValueError, match="gravity"):
        est.estimate(state, gravity=(0.0, math.inf, -9.81))
    with pytest.raises(ValueError, match="qdd"):
        est.estimate(state, qdd=(1.0, 2.0))
    with pytest.raises(ValueError, match="three legs"):
        est.estimate(_state(q[:2], ZERO[:2], [0.1, 0.1]))
    with pytest.raises(ValueError, match="kt_rel_std"):
        ForceErrorBudget(kt_rel_std=-0.1)
    with pytest.raises(ValueError, match="torque_constant_nm_a"):
        ForceEstimator(THESIS_DELTA, torque_constant_nm_a=0.0)
    with pytest.raises(ValueError, match="rotary"):
        force_estimator(LinearDelta(l=0.3, R=0.15, r=0.03))


def _array_estimate(est: ForceEstimator, q, qd, current, gravity, qdd) -> ForceEstimate:
    """The estimate from the kinematics' array functions on a batch of one (1, 3) (their
    vectorised code, not their one-triple paths) and the estimator's NumPy budget: the
    reference the tick's float path must equal."""
    robot, b = est.robot, est.budget
    d = float(dexterity(robot, q[None])[0])
    if not math.isfinite(d):
        return ForceEstimate(reason="joints out of the model's reach (no forward kinematics)")
    if d < est.min_dexterity:
        reason = f"too near a singularity: dexterity {d:.3f} below {est.min_dexterity:g}"
        return ForceEstimate(reason=reason)
    measured = est.kt * current
    friction = np.where(np.abs(qd) > b.moving_rad_s, np.sign(qd) * b.friction_nm, 0.0)
    model = inverse_dynamics_joints(robot, est.mass, q[None], qd[None], qdd[None], gravity)[0]
    force = joint_to_tip_force(robot, q[None], (measured - friction - model)[None])[0]
    std = est.torque_std_nm(measured, model, qd, qdd)
    cov = tip_force_covariance(robot, q[None], std[None])[0]
    return ForceEstimate(force, np.sqrt(np.diag(cov)), True, None, cov)


def test_the_tick_path_is_the_array_path(monkeypatch):
    """estimate() (Python floats, one sample) against the array functions, over 600 seeded
    states of two robots: joints from IK of points over the workspace and random ones
    (some out of reach, some near singularities), speeds with joints at rest and moving,
    accelerations given or not, tilted gravity, and the dexterity gate set a hair above and
    below the state's own. The same outcome and reason; force, std and covariance to 1e-12
    of their size. The float path answers them all (the array fallback is never taken)."""

    def no_fallback(*args, **kwargs):
        raise AssertionError("the array path answered")

    monkeypatch.setattr(ForceEstimator, "_estimate_arrays", no_fallback)
    rng = np.random.default_rng(33)
    other = RotaryDelta(L=0.1, l=0.25, R=0.08, r=0.02)
    outcomes: dict[str, int] = {}
    for base in (force_estimator(THESIS_DELTA, payload_kg=0.1, wrist=True), ForceEstimator(other)):
        robot = base.robot
        for k in range(300):
            if k % 3 == 2:
                q = rng.uniform(-2.5, 3.1, 3)
            else:
                point = rng.uniform((-0.1, -0.1, -0.8 * robot.l), (0.1, 0.1, -0.6 * robot.l))
                q = robot.ik(point).joints
                if not np.isfinite(q).all():
                    continue
            qd = rng.uniform(-2.0, 2.0, 3) * np.where(rng.random(3) < 0.3, 0.01, 1.0)
            qdd = None if k % 2 else rng.uniform(-15.0, 15.0, 3)
            tilt = rng.normal(size=3)
            gravity = 9.81 * tilt / np.linalg.norm(tilt)
            current = rng.uniform(-1.5, 1.5, 3)
            est = base
            d = float(dexterity(robot, q))
            if k % 5 == 0 and math.isfinite(d):  # the gate a hair either side of this state
                est = ForceEstimator(robot, base.mass, min_dexterity=d * (1 + 1e-9 * (-1) ** k))
            got = est.estimate(_state(q, qd, current), gravity=tuple(gravity), qdd=qdd)
            acc = np.zeros(3) if qdd is None else qdd
            want = _array_estimate(est, q, qd, current, gravity, acc)
            assert (got.valid, got.reason) == (want.valid, want.reason)
            key = "valid" if got.valid else (got.reason or "")[:12]
            outcomes[key] = outcomes.get(key, 0) + 1
            if not got.valid:
                assert np.isnan(got.force_n).all() and np.isnan(got.covariance_n2).all()
                continue
            for fast, batch in (
                (got.force_n, want.force_n),
                (got.std_n, want.std_n),
                (got.covariance_n2, want.covariance_n2),
            ):
                assert isinstance(fast, np.ndarray) and fast.shape == batch.shape
                size = np.abs(batch).max()
                np.testing.assert_allclose(fast, batch, rtol=1e-12, atol=1e-12 * size)
    assert outcomes["valid"] >= 300
    assert outcomes["joints out o"] >= 10 and outcomes["too near a s"] >= 40, outcomes


def test_where_the_float_path_declines_the_array_path_answers(monkeypatch):
    """A state the float path gives up on (a singular M, an overflow: mocked here) gets the
    array path's estimate, the same as the float path's where both answer."""
    q = THESIS_DELTA.ik(np.array([0.03, -0.02, -0.25])).joints
    state = _state(q, [0.3, -0.2, 0.0], [0.2, -0.1, 0.3])
    est = ForceEstimator(THESIS_DELTA)
    fast = est.estimate(state, qdd=(1.0, -2.0, 0.5))
    monkeypatch.setattr(app.control.force, "_leg_frame_floats", lambda robot, q: None)
    slow = est.estimate(state, qdd=(1.0, -2.0, 0.5))
    assert fast.valid and slow.valid
    np.testing.assert_allclose(slow.force_n, fast.force_n, rtol=1e-12)
    np.testing.assert_allclose(slow.covariance_n2, fast.covariance_n2, rtol=1e-12)
    far = est.estimate(_state([3.0, 0.0, 0.0], ZERO, [0.1, 0.1, 0.1]))
    assert not far.valid and "out of the model's reach" in (far.reason or "")


# -- against the twin: a force applied to the platform in MuJoCo, the servos holding ------


def _held_twin_reads(point, applied_on_tip, settle_s=1.0):
    """The SimBus read after the twin's servos held `point` with the environment pushing
    the platform by -applied_on_tip [N] (xfrc_applied at its centre) for `settle_s`."""
    from hardware.sim.sim_bus import SimBus, SimBusConfig

    bus = SimBus(SimBusConfig(realtime=False))
    bus.connect()
    twin = bus.twin
    twin.reset(THESIS_DELTA.ik(np.array(point)).joints)
    bus.torque(True)
    twin.data.xfrc_applied[twin.model.body("platform").id, :3] = -np.asarray(applied_on_tip)
    bus.advance(settle_s)
    assert twin.time_s == pytest.approx(settle_s)
    return bus.read_state()


@pytest.mark.parametrize("point", POINTS)
def test_the_twin_at_rest_gives_back_the_applied_force(point):
    est = force_estimator(THESIS_DELTA)
    for force in FORCES:
        got = est.estimate(_held_twin_reads(point, force))
        assert got.valid
        error = got.force_n - np.asarray(force)
        assert (np.abs(error) <= 2.0 * got.std_n).all(), (force, got.force_n, got.std_n)
        assert np.linalg.norm(error) < 0.25  # measured: 0.18 N at most (RMS 0.10)
    idle = est.estimate(_held_twin_reads(point, ZERO))
    assert (np.abs(idle.force_n) <= idle.std_n).all(), (idle.force_n, idle.std_n)


def test_an_unmodelled_payload_on_the_twin_reads_as_its_weight():
    """The check can fail: a 100 g payload on the twin that the loop's model lacks is a
    0.98 N pull on the tip, far outside the std of the estimate."""
    from hardware.sim.masses import THESIS_MASSES
    from hardware.sim.sim_bus import SimBus, SimBusConfig
    from hardware.sim.twin import TwinConfig

    heavy = TwinConfig(masses=THESIS_MASSES.__class__(payload_kg=0.1))
    bus = SimBus(SimBusConfig(twin=heavy, realtime=False))
    bus.connect()
    bus.twin.reset(THESIS_DELTA.ik(np.array([0.0, 0.0, -0.26])).joints)
    bus.torque(True)
    bus.advance(1.0)
    got = force_estimator(THESIS_DELTA).estimate(bus.read_state())
    assert got.force_n[2] == pytest.approx(0.981, abs=0.15)
    assert got.force_n[2] > 3 * got.std_n[2]
    loaded = force_estimator(THESIS_DELTA, payload_kg=0.1).estimate(bus.read_state())
    assert abs(loaded.force_n[2]) <= loaded.std_n[2]


@pytest.mark.slow  # three seconds of simulated time
def test_the_twin_while_moving_stays_within_the_documented_bound():
    """A 30 mm, 1 Hz sinusoid along z with 2 N pressing down: with the commanded qdd, the
    RMS error stays within sqrt(3) std (the ripple is common to the three joints, module
    doc); with qdd taken as zero it is larger."""
    from hardware.sim.sim_bus import SimBus, SimBusConfig

    bus = SimBus(SimBusConfig(realtime=False))
    bus.connect()
    twin = bus.twin
    centre, amplitude, w = np.array([0.0, 0.0, -0.24]), np.array([0.0, 0.0, 0.03]), 2 * np.pi
    twin.reset(THESIS_DELTA.ik(centre).joints)
    bus.torque(True)
    applied = np.array([0.0, 0.0, -2.0])
    twin.data.xfrc_applied[twin.model.body("platform").id, :3] = -applied
    bus.advance(0.5)
    est = force_estimator(THESIS_DELTA)
    errors, stds, zero_qdd = [], [], []
    for k in range(300):
        t, ramp = k * 0.01, min(1.0, k * 0.01)
        p = centre + ramp * amplitude * np.sin(w * t)
        pd = ramp * amplitude * w * np.cos(w * t)
        pdd = -ramp * amplitude * w * w * np.sin(w * t)
        motion = joint_motion(THESIS_DELTA, p, pd, pdd)
        bus.write_goal(motion.joints)
        bus.advance(0.01)
        state = bus.read_state()
        if t < 1.2:
            continue
        got = est.estimate(state, qdd=motion.accelerations)
        assert got.valid
        errors.append(got.force_n - applied)
        stds.append(got.std_n)
        zero_qdd.append(est.estimate(state).force_n - applied)
    rms = np.sqrt(np.mean(np.square(errors), axis=0))
    assert (rms <= math.sqrt(3) * np.mean(stds, axis=0)).all(), (rms, np.mean(stds, axis=0))
    assert rms[2] < 0.6  # measured 0.43 N
    assert np.sqrt(np.mean(np.square(zero_qdd), axis=0))[2] > rms[2]

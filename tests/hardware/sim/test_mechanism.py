"""The generated MuJoCo mechanism: assembly, masses, closed chains, statics and dynamics."""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from hardware.sim.base_frame import BaseMotion
from hardware.sim.masses import DeltaMasses, gravity_torques
from hardware.sim.mjcf import SimOptions, build_mjcf
from hardware.sim.twin import DeltaTwin, TwinConfig
from hardware.sim.xm430 import XM430_W210
from kinematics import THESIS_DELTA, RotaryDelta

OTHER_DESIGN = RotaryDelta(L=0.12, l=0.30, R=0.10, r=0.03)


@pytest.mark.parametrize(
    ("robot", "home"), [(THESIS_DELTA, (0.0, 0.0, -0.24)), (OTHER_DESIGN, (0.02, -0.03, -0.27))]
)
def test_assembled_model_has_thesis_joints_and_closed_chains(robot, home) -> None:
    model = mujoco.MjModel.from_xml_string(build_mjcf(robot, options=SimOptions(home_m=home)))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    theta = [data.joint(f"motor_{i}").qpos[0] for i in (1, 2, 3)]
    assert theta == pytest.approx(robot.ik(np.array(home)).joints, abs=1e-12)
    platform = [data.joint(f"platform_{a}").qpos[0] for a in "xyz"]
    assert platform == pytest.approx(home, abs=1e-12)
    for i in (1, 2, 3):
        gap = data.site(f"rod_end_{i}").xpos - data.site(f"ankle_{i}").xpos
        assert np.linalg.norm(gap) < 1e-8  # 10 nm: the file holds 12 significant digits


def test_moving_mass_is_the_mass_model() -> None:
    masses = DeltaMasses(payload_kg=0.2)
    model = mujoco.MjModel.from_xml_string(build_mjcf(THESIS_DELTA, masses))
    moving = sum(model.body(n).mass[0] for n in ("platform", "upper_1", "lower_1")) + 2 * sum(
        model.body(f"{part}_{i}").mass[0] for part in ("upper", "lower") for i in (2,)
    )
    assert moving == pytest.approx(0.025 + 0.2 + 3 * (0.029 + 2 * 0.0105))


def test_gravity_torques_are_the_gradient_of_potential_energy() -> None:
    # independent of the Jacobian: U from heights of platform, knees and link centres
    robot, m = THESIS_DELTA, DeltaMasses(payload_kg=0.1)

    def potential(q: np.ndarray) -> float:
        z_p = robot.fk(q).points[2]
        z_knees = -robot.L * np.sin(q)
        per_leg = m.upper_kg * z_knees / 2 + m.lower_kg * (z_knees + z_p) / 2
        return 9.81 * (m.platform_total_kg * z_p + per_leg.sum())

    q, h = np.array([0.3, 0.5, 0.7]), 1e-6
    gradient = [(potential(q + h * e) - potential(q - h * e)) / (2 * h) for e in np.eye(3)]
    assert gravity_torques(robot, m, q) == pytest.approx(gradient, rel=1e-6)


def frictionless(payload_kg: float = 0.0) -> DeltaTwin:
    servo = replace(XM430_W210, coulomb_friction_nm=0.0)
    return DeltaTwin(TwinConfig(masses=DeltaMasses(payload_kg=payload_kg), servo=servo))


@pytest.mark.parametrize(
    ("joints", "attitude", "payload"),
    [
        ((0.5, 0.5, 0.5), (1.0, 0.0, 0.0, 0.0), 0.0),
        ((0.3, 0.6, 0.8), (1.0, 0.0, 0.0, 0.0), 0.2),
        ((0.5, 0.4, 0.6), (np.cos(0.2), np.sin(0.2), 0.0, 0.0), 0.1),  # drone rolled 23 deg
    ],
)
def test_holding_at_rest_the_servos_deliver_the_gravity_torques(joints, attitude, payload) -> None:
    twin = frictionless(payload)
    twin.set_base_motion(BaseMotion(attitude_wxyz=attitude))
    twin.reset(joints)
    twin.advance(0.3)
    torques = mean_torques(twin)
    expected = gravity_torques(
        THESIS_DELTA, twin.config.masses, twin.joints_rad, twin.model.opt.gravity
    )
    assert torques == pytest.approx(expected, rel=0.03, abs=2e-3)
    assert np.abs(twin.joint_velocity_rad_s).max() < 0.05


def mean_torques(twin: DeltaTwin, steps: int = 500) -> np.ndarray:
    torques = []
    for _ in range(steps):  # the P loop dithers between encoder ticks: average it
        twin.step()
        torques.append([o.torque_nm for o in twin.outputs])
    return np.mean(torques, axis=0)


def test_an_accelerating_base_weighs_like_stronger_gravity() -> None:
    level, lifting = frictionless(), frictionless()
    lifting.set_base_motion(
        BaseMotion(acceleration_m_s2=(0.0, 0.0, 9.81))
    )  # 1 g upwards: twice the weight
    assert lifting.model.opt.gravity == pytest.approx([0.0, 0.0, -2 * 9.81])
    for twin in (level, lifting):
        twin.advance(0.3)
    assert mean_torques(lifting) == pytest.approx(2 * mean_torques(level), rel=0.05)


def test_a_turning_base_adds_the_centrifugal_torques() -> None:
    # steady spin about the base's z axis: at rest in the base frame the servos hold
    # gravity plus the centrifugal pull, i.e. the gradient of U = sum m (-g.c - |w x c|^2 / 2)
    # over the bodies' centres of mass c (platform, upper links at L/2, rods at mid-length)
    robot, masses, spin = THESIS_DELTA, DeltaMasses(payload_kg=0.1), np.array([0.0, 0.0, 8.0])
    g = np.array([0.0, 0.0, -9.81])

    def potential(q: np.ndarray, w: np.ndarray) -> float:
        hips, knees, ankles = robot.leg_points(q)
        centres = [(masses.platform_total_kg, robot.fk(q).points)]
        centres += [(masses.upper_kg, (h + k) / 2) for h, k in zip(hips, knees, strict=True)]
        centres += [(masses.lower_kg, (k + a) / 2) for k, a in zip(knees, ankles, strict=True)]
        return sum(m * (-g @ c - 0.5 * np.sum(np.cross(w, c) ** 2)) for m, c in centres)

    def holding(q: np.ndarray, w: np.ndarray) -> np.ndarray:
        h = 1e-6
        return np.array(
            [(potential(q + h * e, w) - potential(q - h * e, w)) / (2 * h) for e in np.eye(3)]
        )

    twin = frictionless(0.1)
    twin.set_base_motion(BaseMotion(angular_velocity_rad_s=tuple(spin)))
    twin.reset((0.3, 0.6, 0.8))
    twin.advance(0.3)
    q = twin.joints_rad
    expected, still = holding(q, spin), holding(q, np.zeros(3))
    assert np.abs(expected - still).max() > 0.1 * np.abs(still).max()  # the spin matters
    assert mean_torques(twin) == pytest.approx(expected, rel=0.03, abs=2e-3)


def test_frame_forces_use_each_body_s_own_velocity():
    """The vectorized Euler/centrifugal/Coriolis forces equal the per-body definition,
    with each centre of mass's velocity from mj_objectVelocity, on a moving arm."""
    from hardware.sim.base_frame import apply_frame_forces

    motion = BaseMotion(
        angular_velocity_rad_s=(0.4, -0.7, 1.1), angular_acceleration_rad_s2=(2.0, 0.5, -1.5)
    )
    twin = frictionless(0.1)
    twin.reset((0.2, 0.7, 1.0))
    twin.advance(0.05)  # falling: every body moves
    model, data, bodies = twin.model, twin.data, twin._moving_bodies
    apply_frame_forces(model, data, bodies, motion)
    w, w_dot = np.array(motion.angular_velocity_rad_s), np.array(motion.angular_acceleration_rad_s2)
    velocity = np.zeros(6)
    for body in bodies:
        r = data.xipos[body]
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, velocity, 0)
        assert np.linalg.norm(velocity[3:]) > 1e-3
        accel = np.cross(w_dot, r) + np.cross(w, np.cross(w, r)) + 2 * np.cross(w, velocity[3:])
        np.testing.assert_allclose(
            data.xfrc_applied[body, :3], -model.body_mass[body] * accel, rtol=1e-9, atol=1e-12
        )

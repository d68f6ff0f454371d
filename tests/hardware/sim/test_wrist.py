"""The twin's wrist: a fourth XM430 on the platform turning the tool about the platform's z."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import mujoco
import numpy as np
import pytest

from hardware.calibration import JointCalibration
from hardware.dynamixel.control_table import RAD_PER_TICK
from hardware.sim.masses import THESIS_MASSES, WRIST_XM430, DeltaMasses, gravity_torques
from hardware.sim.mjcf import WRIST_JOINT, build_mjcf
from hardware.sim.process_bus import ProcessSimBus
from hardware.sim.sim_bus import SimBus, SimBusConfig
from hardware.sim.twin import DeltaTwin, TwinConfig
from hardware.sim.xm430 import XM430_W210
from kinematics import THESIS_DELTA
from tests.support.wait import wait_for

LEGS = tuple(JointCalibration(i) for i in (1, 2, 3))
# a wrist mounted the other way round, a quarter turn off the middle of its encoder
WRIST = JointCalibration(4, zero_offset_ticks=1024, direction=-1, min_angle_rad=-1.5,
                         max_angle_rad=3.0)  # fmt: skip
WITH_WRIST = TwinConfig(joints=(*LEGS, WRIST))


@pytest.fixture
def bus() -> Iterator[SimBus]:
    sim = SimBus(SimBusConfig(twin=WITH_WRIST, realtime=False, torque_on_at_start=True))
    sim.connect()
    yield sim
    sim.disconnect()


def advance_until(bus: SimBus, done, limit_s: float = 3.0, step_s: float = 0.02) -> float:
    """Step simulated time until ``done(state)``; the simulated time it took [s]."""
    t = 0.0
    while not done(bus.read_state()):
        assert t < limit_s, f"not reached within {limit_s} s simulated: {bus.read_state()}"
        bus.advance(step_s)
        t += step_s
    return t


def test_a_fourth_calibration_adds_the_xm430_wrist_masses_to_the_platform() -> None:
    assert not TwinConfig().masses.has_wrist
    masses = WITH_WRIST.masses
    assert (masses.wrist_servo_kg, masses.wrist_kg) == (0.082, 0.020)  # XM430-W210, tool
    assert masses.platform_total_kg == pytest.approx(0.025 + 0.082 + 0.020)
    # the dynamics' mass model (kinematics.dynamics) carries them too
    assert masses.mass_model(THESIS_DELTA.L).platform_kg == pytest.approx(0.127)
    with pytest.raises(ValueError, match="fourth joint calibration"):
        TwinConfig(masses=THESIS_MASSES.with_wrist())


def test_the_wrist_body_turns_about_the_platform_z_with_its_mass_and_inertia() -> None:
    masses = THESIS_MASSES.with_wrist()
    model = mujoco.MjModel.from_xml_string(build_mjcf(THESIS_DELTA, masses))
    wrist = model.body("wrist")
    assert model.body(wrist.parentid[0]).name == "platform"
    assert wrist.mass[0] == pytest.approx(WRIST_XM430.turning_kg)
    assert wrist.inertia[2] == pytest.approx(WRIST_XM430.turning_inertia_kgm2)
    joint = model.joint(WRIST_JOINT)
    assert list(joint.axis) == [0.0, 0.0, 1.0] and model.nu == 4
    # the platform's body holds the rest: case of the servo, platform, payload
    assert model.body("platform").mass[0] == pytest.approx(0.025 + 0.082)
    # without a wrist the model is as before
    plain = mujoco.MjModel.from_xml_string(build_mjcf(THESIS_DELTA, THESIS_MASSES))
    assert plain.nu == 3 and plain.body("platform").mass[0] == pytest.approx(0.025)


def test_the_legs_hold_the_wrist_s_weight_as_the_statics_say() -> None:
    # frictionless servos at rest: their torques are the gravity torques of the heavier
    # platform (virtual work with platform_total_kg, which includes the wrist)
    servo = replace(XM430_W210, coulomb_friction_nm=0.0)
    twin = DeltaTwin(replace(WITH_WRIST, servo=servo))
    twin.reset([0.5, 0.5, 0.5, 0.0])
    twin.advance(0.3)
    torques = []
    for _ in range(500):  # the P loop dithers between encoder ticks: average it
        twin.step()
        torques.append([o.torque_nm for o in twin.outputs])
    legs = np.mean(torques, axis=0)[:3]
    expected = gravity_torques(THESIS_DELTA, twin.config.masses, twin.joints_rad[:3])
    without = gravity_torques(THESIS_DELTA, DeltaMasses(), twin.joints_rad[:3])
    assert legs == pytest.approx(expected, rel=0.03, abs=2e-3)
    assert np.all(np.abs(expected - without) > 0.01)  # the wrist's 102 g are felt


def test_the_wrist_turns_to_a_commanded_phi_and_holds_it(bus: SimBus) -> None:
    start = bus.read_state()
    assert start.position_rad.shape == (4,)
    legs = start.position_rad[:3]
    bus.write_goal([*legs, 1.2])
    advance_until(bus, lambda s: abs(s.position_rad[3] - 1.2) <= 3 * RAD_PER_TICK)
    bus.advance(1.0)  # and it stays there, the legs too
    state = bus.read_state()
    assert state.position_rad[3] == pytest.approx(1.2, abs=3 * RAD_PER_TICK)
    assert state.position_rad[:3] == pytest.approx(legs, abs=8 * RAD_PER_TICK)
    # through the calibration: the shaft turned the other way from 1024 ticks
    assert bus.twin.shaft_rad[3] / RAD_PER_TICK == pytest.approx(1024 - 1.2 / RAD_PER_TICK, abs=4)
    assert bus.twin.joints_rad[3] == pytest.approx(1.2, abs=3 * RAD_PER_TICK)
    # the platform is not turned or pushed by the wrist's reaction
    assert bus.twin.platform_m[:2] == pytest.approx([0.0, 0.0], abs=1e-4)


def test_a_wrist_goal_beyond_its_limits_is_clamped_like_a_leg_s(bus: SimBus) -> None:
    legs = bus.read_state().position_rad[:3]
    bus.write_goal([*legs, 5.0])
    advance_until(bus, lambda s: abs(s.position_rad[3] - 3.0) <= 3 * RAD_PER_TICK)


@pytest.mark.slow
def test_the_process_bus_carries_four_servos() -> None:
    sim = ProcessSimBus(SimBusConfig(twin=WITH_WRIST, torque_on_at_start=True))
    sim.connect()
    try:
        state = sim.read_state()
        assert state.position_rad.shape == (4,) and len(state.hardware_errors) == 4
        legs = state.position_rad[:3]
        sim.write_goal([*legs, -0.8])
        wait_for(
            lambda: abs(sim.read_state().position_rad[3] + 0.8) <= 3 * RAD_PER_TICK,
            "the wrist at -0.8 rad in the simulator process",
            timeout_s=30.0,
            seen=lambda: sim.read_state().position_rad,
        )
    finally:
        sim.disconnect()

"""A twin built wrong on purpose: joint offsets and per-leg geometry the controller does not
know, and motion capture in a frame of its own (the ground truth of a calibration)."""

from __future__ import annotations

import numpy as np

from hardware.sim.sim_bus import SimBus, SimBusConfig
from hardware.sim.twin import DeltaTwin, TwinConfig
from kinematics import THESIS_DELTA, PerLegRotaryDelta
from kinematics.identification import MeasurementFrame

TRUE_ROBOT = PerLegRotaryDelta.from_symmetric(
    THESIS_DELTA,
    joint_offsets_rad=np.radians([3.0, -2.0, 4.0]),
    l=(0.2440, 0.2430, 0.2425),
    R=(0.0844, 0.0850, 0.0844),
)
GOALS = np.array([[0.0, 0.0, -0.24], [0.05, -0.03, -0.21], [-0.04, 0.05, -0.28]])
COMPLIANCE_M = 2e-5  # chain stretch and a settling servo: ~1 um measured at rest, 1 um stretch


def _settle(bus: SimBus, joints: np.ndarray) -> np.ndarray:
    """Hold the controller's `joints` until the arm is still; its reported joints [rad]."""
    bus.write_goal(joints)
    bus.advance(1.5)
    return bus.twin.joints_of_shafts(bus.twin.shaft_rad) - TRUE_ROBOT.joint_offsets_rad


def test_the_platform_is_where_the_true_geometry_puts_it() -> None:
    """Per-leg FK of what the servos report, with the true parameters, finds the platform;
    the nominal FK the controller uses misses it by millimetres."""
    bus = SimBus(
        SimBusConfig(
            twin=TwinConfig(true_robot=TRUE_ROBOT), realtime=False, torque_on_at_start=True
        )
    )
    bus.connect()
    try:
        for goal in GOALS:
            reported = _settle(bus, THESIS_DELTA.ik(goal).joints)
            # what the bus says is what the servos say: the unrounded value within a tick
            np.testing.assert_allclose(bus.read_state().position_rad, reported, atol=1e-3)
            platform = bus.twin.platform_m
            true_fk = TRUE_ROBOT.fk(reported).points
            assert np.linalg.norm(platform - true_fk) < COMPLIANCE_M
            assert np.linalg.norm(platform - THESIS_DELTA.fk(reported).points) > 3e-3
    finally:
        bus.disconnect()


def test_the_mechanism_has_the_true_legs() -> None:
    """The chains close with each leg's own rod: |ankle - knee| = l_i in the model."""
    twin = DeltaTwin(TwinConfig(true_robot=TRUE_ROBOT))
    theta = np.array([0.3, 0.5, 0.7])
    twin.reset(theta)  # true angles theta
    np.testing.assert_allclose(twin.joints_rad, theta, atol=1e-6)
    mechanism = TRUE_ROBOT.with_values(joint_offsets_rad=(0.0, 0.0, 0.0))
    assert np.linalg.norm(twin.platform_m - mechanism.fk(theta).points) < 1e-5
    assert twin.constraint_error_m() < 1e-5
    # the servos read theta - o: the offsets sit between mechanism and encoders
    reported = twin.joints_of_shafts(twin.shaft_rad) - TRUE_ROBOT.joint_offsets_rad
    np.testing.assert_allclose(reported, theta - TRUE_ROBOT.joint_offsets_rad, atol=1e-12)


def test_external_measurement_is_in_its_own_frame() -> None:
    frame = MeasurementFrame((0.3, -0.1, -0.5), (0.05, -0.02, 1.2))
    marker = (0.0, 0.0, -0.02)
    bus = SimBus(
        SimBusConfig(
            realtime=False,
            torque_on_at_start=True,
            marker_offset_m=marker,
            measurement_frame_position_m=frame.position_m,
            measurement_frame_rpy_rad=frame.rpy_rad,
        )
    )
    bus.connect()
    measured = bus.measure_platform()
    np.testing.assert_allclose(frame.to_base(measured), bus.twin.platform_m + marker, atol=1e-15)
    assert np.linalg.norm(measured - bus.twin.platform_m) > 0.1  # not the base frame's numbers
    bus.disconnect()


def test_the_defaults_are_the_exact_twin() -> None:
    exact, default = DeltaTwin(), DeltaTwin(TwinConfig(true_robot=None))
    assert TwinConfig().built == THESIS_DELTA
    np.testing.assert_array_equal(exact.shaft_rad, default.shaft_rad)
    same = DeltaTwin(TwinConfig(true_robot=PerLegRotaryDelta.from_symmetric(THESIS_DELTA)))
    np.testing.assert_allclose(same.platform_m, exact.platform_m, atol=1e-12)
    np.testing.assert_allclose(same.shaft_rad, exact.shaft_rad, atol=1e-12)

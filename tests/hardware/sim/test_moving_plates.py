"""Plates that move: set by hand (DeltaTwin / SimBus / ProcessSimBus.set_plate_pose) or fixed
in the world while the base drifts (BaseMotion.position_m). Checked against MuJoCo's own
contact force and state, in simulated time (the process bus excepted: it follows the wall
clock, so its test waits for states, never for time)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from app.config import ConfigError, load_settings
from app.server.backends import _twin
from app.world.drone_sim import DroneSimParams, SimulatedDrone
from app.world.hold import SimulatedDroneProvider
from app.world.service import base_motion
from hardware.base_motion import BaseMotion, rotation
from hardware.sim import ProcessSimBus, SimBus, SimBusConfig
from hardware.sim.mjcf import TIP_GEOM, plate_name
from hardware.sim.surfaces import TIP_RADIUS_M, Plate
from hardware.sim.twin import DeltaTwin, TwinConfig
from kinematics import THESIS_DELTA, Pose
from tests.hardware.sim.test_surfaces import command_tip
from tests.support.wait import wait_for

FLOOR = Plate(point_m=(0.0, 0.0, -0.26), stiffness_n_m=1.0e4, damping_n_s_m=20.0)
MOUNT = Pose.from_arrays((0.0, 0.0, -0.08))


def tip_centre(twin: DeltaTwin) -> np.ndarray:
    return twin.data.geom_xpos[twin.model.geom(TIP_GEOM).id].copy()


def depth_m(twin: DeltaTwin, index: int = 0) -> float:
    """The tip sphere's depth in plate `index` where MuJoCo has the plate now (its qpos)."""
    point, normal = twin.plate_pose(index)
    return TIP_RADIUS_M - float((tip_centre(twin) - point) @ normal)


def pressing_at_rest(twin: DeltaTwin, seconds: float = 1.5) -> float:
    twin.advance(seconds)
    assert np.abs(twin.joint_velocity_rad_s).max() < 1e-3
    return -float(twin.contact().force_n[2])


# -- set by hand ---------------------------------------------------------------------------
def test_a_plate_moved_up_under_the_tip_presses_harder_by_its_stiffness() -> None:
    twin = DeltaTwin(TwinConfig(plates=(FLOOR,)))
    command_tip(twin, (0.0, 0.0, -0.262))  # 2 mm into the plate
    before = pressing_at_rest(twin)
    depth_before, tip_before = depth_m(twin), tip_centre(twin)
    assert before == pytest.approx(FLOOR.stiffness_n_m * depth_before, rel=1e-3)

    twin.set_plate_pose(0, (0.0, 0.0, -0.257), (0.0, 0.0, 1.0))  # 3 mm up
    point, normal = twin.plate_pose(0)
    np.testing.assert_array_equal(point, [0.0, 0.0, -0.257])
    np.testing.assert_allclose(normal, [0.0, 0.0, 1.0], atol=1e-15)
    after = pressing_at_rest(twin)
    # MuJoCo's plate stayed where it was put, under the tip's push, to the last bit
    np.testing.assert_array_equal(twin.plate_pose(0)[0], point)
    # the same force law at the new place: the force rose by stiffness * (3 mm less what
    # the servos gave way, measured from the tip's own rise)
    rise = float(tip_centre(twin)[2] - tip_before[2])
    assert 0.0 < rise < 0.003
    assert after == pytest.approx(FLOOR.stiffness_n_m * depth_m(twin), rel=1e-3)
    assert after - before == pytest.approx(FLOOR.stiffness_n_m * (0.003 - rise), rel=2e-3)
    assert depth_m(twin) - depth_before == pytest.approx(0.003 - rise, abs=1e-7)

    twin.set_plate_pose(0, (0.0, 0.0, -0.30), (0.0, 0.0, 1.0))  # away: the contact ends
    twin.advance(0.5)
    contact = twin.contact()
    assert not contact.in_contact and contact.point_m is None
    assert np.array_equal(contact.force_n, np.zeros(3))


def test_a_plate_can_be_turned_and_its_box_follows() -> None:
    twin = DeltaTwin(TwinConfig(plates=(FLOOR,)))
    normal = np.array([0.3, -0.4, 0.8]) / np.linalg.norm([0.3, -0.4, 0.8])
    twin.set_plate_pose(0, (0.01, 0.02, -0.3), normal * 2.0)  # any length
    point, seen = twin.plate_pose(0)
    np.testing.assert_allclose(seen, normal, atol=1e-12)
    geom = twin.model.geom(plate_name(0)).id
    frame = twin.data.geom_xmat[geom].reshape(3, 3)
    expected = Plate(point_m=(0.01, 0.02, -0.3), normal=tuple(normal)).frame()
    np.testing.assert_allclose(frame, expected, atol=1e-12)  # Plate.frame's in-face axes
    top = twin.data.geom_xpos[geom] + frame[:, 2] * twin.model.geom_size[geom, 2]
    np.testing.assert_allclose(top, [0.01, 0.02, -0.3], atol=1e-12)


def test_a_moving_plate_moves_at_its_speed_and_the_contact_sees_it() -> None:
    twin = DeltaTwin(TwinConfig(plates=(FLOOR,)))
    command_tip(twin, (0.0, 0.0, -0.262))
    pressing_at_rest(twin, 1.0)
    speed = np.array([0.0, 0.0, 0.05])  # the plate rising at 5 cm/s
    twin.set_plate_pose(0, FLOOR.point_m, FLOOR.normal, velocity_m_s=speed)
    start = twin.time_s
    twin.step(10)
    point, _ = twin.plate_pose(0)
    np.testing.assert_allclose(point, np.array(FLOOR.point_m) + speed * (twin.time_s - start))
    # the contact's normal speed (MuJoCo's efc_vel, separating > 0, its normal from the tip
    # to the plate), the state taken at one instant: the tip's relative to the plate
    twin._hold_plates()  # noqa: SLF001 (as the next step starts)
    mujoco.mj_forward(twin.model, twin.data)
    (i,) = range(twin.data.ncon)
    row = twin.data.contact[i].efc_address
    tip_speed = twin.data.qvel[twin._platform_q]  # noqa: SLF001 (the tip rides the platform)
    normal_speed = float(twin.data.efc_vel[row])
    assert normal_speed == pytest.approx(float(tip_speed[2] - speed[2]), abs=1e-9)
    assert abs(normal_speed) > 0.01  # not the tip's speed alone: the plate's counts

    # turning about its point: the normal turns at the rate given (about x, 0.5 rad/s)
    twin.set_plate_pose(0, (0.0, 0.0, -0.3), (0.0, 0.0, 1.0), angular_velocity_rad_s=(0.5, 0, 0))
    start = twin.time_s
    twin.step(200)
    angle = 0.5 * (twin.time_s - start)
    np.testing.assert_allclose(
        twin.plate_pose(0)[1], [0.0, -np.sin(angle), np.cos(angle)], atol=1e-9
    )
    np.testing.assert_allclose(twin.plate_pose(0)[0], [0.0, 0.0, -0.3], atol=1e-12)


@pytest.mark.parametrize(
    ("args", "field"),
    [
        ((1, (0, 0, -0.3), (0, 0, 1)), "plate index"),
        ((-1, (0, 0, -0.3), (0, 0, 1)), "plate index"),
        ((True, (0, 0, -0.3), (0, 0, 1)), "plate index"),
        ((0, (0, float("nan"), -0.3), (0, 0, 1)), "point_m"),
        ((0, (0, 0), (0, 0, 1)), "point_m"),
        ((0, (0, 0, -0.3), (0, 0, 0)), "normal"),
        ((0, (0, 0, -0.3), (0, 0, 1), (0, 0, float("inf"))), "velocity_m_s"),
        ((0, (0, 0, -0.3), (0, 0, 1), (0, 0, 0), (1, 2)), "angular_velocity_rad_s"),
    ],
)
def test_a_bad_plate_pose_is_refused_naming_the_field(args, field) -> None:
    twin = DeltaTwin(TwinConfig(plates=(FLOOR,)))
    with pytest.raises(ValueError, match=field):
        twin.set_plate_pose(*args)
    np.testing.assert_array_equal(twin.plate_pose(0)[0], FLOOR.point_m)  # unmoved


def test_the_sim_bus_moves_a_plate() -> None:
    bus = SimBus(SimBusConfig(twin=TwinConfig(plates=(FLOOR,)), realtime=False))
    bus.connect()
    bus.write_goal(list(THESIS_DELTA.ik(np.array([0.0, 0.0, -0.262])).joints))
    bus.advance(1.0)
    assert bus.measure_contact().in_contact
    bus.set_plate_pose(0, (0.0, 0.0, -0.3), (0.0, 0.0, 1.0))
    bus.advance(0.2)
    assert not bus.measure_contact().in_contact
    with pytest.raises(ValueError, match="plate index"):
        bus.set_plate_pose(3, (0.0, 0.0, -0.3), (0.0, 0.0, 1.0))
    bus.disconnect()


@pytest.mark.slow
def test_the_process_bus_moves_a_plate_in_its_child() -> None:
    bus = ProcessSimBus(SimBusConfig(twin=TwinConfig(plates=(FLOOR,)), torque_on_at_start=True))
    bus.connect()
    try:
        bus.write_goal(list(THESIS_DELTA.ik(np.array([0.0, 0.0, -0.262])).joints))
        wait_for(lambda: bus.measure_contact().in_contact, "the tip to press the plate")
        bus.set_plate_pose(0, (0.0, 0.0, -0.3), (0.0, 0.0, 1.0))
        # answered: the next frame published after the reply has it (no contact)
        state = bus.read_state()
        wait_for(
            lambda: bus.read_state().sim_time_s > state.sim_time_s + 0.05,
            "the simulator to step on",
        )
        assert not bus.measure_contact().in_contact
        with pytest.raises(ValueError, match="plate index"):
            bus.set_plate_pose(1, (0.0, 0.0, -0.3), (0.0, 0.0, 1.0))
        with pytest.raises(ValueError, match="normal"):
            bus.set_plate_pose(0, (0.0, 0.0, -0.3), (0.0, 0.0, 0.0))
    finally:
        bus.disconnect()


# -- fixed in the world ----------------------------------------------------------------------
WALL = Plate(
    point_m=(0.05, 0.0, -0.26), normal=(-1.0, 0.0, 0.0), half_size_m=(0.05, 0.03), fixed_in="world"
)


def test_fixed_in_is_base_or_world() -> None:
    assert FLOOR.fixed_in == "base"
    with pytest.raises(ValueError, match="fixed_in"):
        Plate(point_m=(0.0, 0.0, -0.26), fixed_in="drone")


def expected_in_base(plate: Plate, anchor: BaseMotion, now: BaseMotion):
    """base^-1 * base_0 * plate (point, rotation), computed here from the poses sent."""
    world = Pose.from_arrays(anchor.position_m, anchor.attitude_wxyz)
    base = Pose.from_arrays(now.position_m, now.attitude_wxyz)
    point = base.apply_inverse(world.apply(np.array(plate.point_m)))
    turn = base.rotation.T @ world.rotation @ plate.frame()
    return point, turn


def test_a_world_plate_follows_the_drifting_drone_inversely() -> None:
    twin = DeltaTwin(TwinConfig(plates=(FLOOR, WALL)))
    sent: list[BaseMotion] = []

    def feel(*args) -> None:
        sent.append(base_motion(MOUNT, *args))
        twin.set_base_motion(sent[-1])

    drone = SimulatedDrone(DroneSimParams(drift_m=0.03, tilt_deg=4.0, yaw_deg=5.0, seed=3))
    provider = SimulatedDroneProvider(drone, feel, pose=True)
    dt, moved = 0.005, []
    for k in range(1, 401):  # 2 s at the loop's 200 Hz
        provider.observe(k * dt)
        now = sent[-1]
        point, turn = expected_in_base(WALL, sent[0], now)
        seen, normal = twin.plate_pose(1)
        np.testing.assert_allclose(seen, point, atol=1e-9)
        np.testing.assert_allclose(normal, turn[:, 2], atol=1e-9)
        geom = twin.model.geom(plate_name(1)).id
        twin.step()  # MuJoCo places the box (and the frame within) as sent
        np.testing.assert_allclose(twin.data.geom_xmat[geom].reshape(3, 3), turn, atol=1e-9)
        # the floor is fixed in the base: it never moves
        np.testing.assert_array_equal(twin.plate_pose(0)[0], FLOOR.point_m)
        twin.step(4)
        moved.append(np.linalg.norm(seen - np.array(WALL.point_m)))
    # sent from the drone's own pose: position, attitude, mount
    first = drone.true_state(dt)[0] @ MOUNT
    np.testing.assert_allclose(sent[0].position_m, first.position, atol=1e-12)
    np.testing.assert_allclose(twin.world_anchor[0], first.position, atol=1e-12)
    assert max(moved) > 0.005  # it really drifted (mm to cm)
    # a base motion without a pose puts the wall back where configured
    twin.set_base_motion(BaseMotion())
    np.testing.assert_allclose(twin.plate_pose(1)[0], WALL.point_m, atol=1e-15)
    assert twin.world_anchor is None


def test_between_poses_a_world_plate_moves_on_at_the_velocity_of_a_world_point() -> None:
    twin = DeltaTwin(TwinConfig(plates=(WALL,)))
    drone = SimulatedDrone(DroneSimParams(drift_m=0.03, tilt_deg=4.0, yaw_deg=5.0, seed=5))
    sent: list[BaseMotion] = []

    def feel(*args) -> None:
        sent.append(base_motion(MOUNT, *args))
        twin.set_base_motion(sent[-1])

    provider = SimulatedDroneProvider(drone, feel, pose=True)
    provider.observe(1.0)
    provider.observe(1.0 + 0.005)  # one loop period later: the anchor is the first pose
    twin.step(5)  # 5 ms of the plate's own motion, from the velocity sent
    drifted = twin.plate_pose(0)[0]
    provider.observe(1.0 + 0.010)  # the next pose, where the wall truly is then
    truth = twin.plate_pose(0)[0]
    still = expected_in_base(WALL, sent[0], sent[1])[0]
    # the velocity carries it most of the way: what is left is second order (0.1 mm
    # moved in 5 ms, a few um left)
    assert np.linalg.norm(truth - still) > 5e-5
    assert np.linalg.norm(truth - drifted) < 0.1 * np.linalg.norm(truth - still)


def test_a_config_plate_can_be_fixed_in_the_world(tmp_path) -> None:
    path = tmp_path / "wall.toml"
    path.write_text(
        "[hardware]\nsim_process = false\n[[hardware.sim.plates]]\n"
        'point_m = [0.05, 0.0, -0.26]\nnormal = [-1.0, 0.0, 0.0]\nfixed_in = "world"\n'
    )
    twin = _twin(load_settings(path), realtime=False).twin
    (wall,) = twin.config.plates
    assert wall.fixed_in == "world"
    assert (
        load_settings(hardware={"sim": {"plates": [{"point_m": [0, 0, -0.26]}]}})
        .hardware.sim.plates[0]
        .fixed_in
        == "base"
    )
    path.write_text('[[hardware.sim.plates]]\npoint_m = [0.0, 0.0, -0.26]\nfixed_in = "drone"\n')
    with pytest.raises(ConfigError, match=r"hardware\.sim\.plates\.0\.fixed_in"):
        load_settings(path)


def test_a_base_pose_needs_finite_numbers() -> None:
    with pytest.raises(ValueError, match="position_m"):
        BaseMotion(position_m=(0.0, float("nan"), 1.5))
    with pytest.raises(ValueError, match="velocity_m_s"):
        BaseMotion(position_m=(0.0, 0.0, 1.5), velocity_m_s=(1.0, 2.0))
    assert rotation((1.0, 0.0, 0.0, 0.0)).shape == (3, 3)

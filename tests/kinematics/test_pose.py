"""Drone-mounted frames (kinematics/pose.py, thesis eq. 5.1-5.2) against hand-computed cases."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from kinematics import Pose, PoseError, base_to_world, world_to_base
from kinematics.pose import unit_quaternion

S = math.sqrt(0.5)


def _about(axis: str, degrees: float) -> list[float]:
    half = math.radians(degrees) / 2
    vector = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1]}[axis]
    return [math.cos(half), *(math.sin(half) * np.array(vector))]


@pytest.mark.parametrize(
    ("axis", "world", "base"),
    [
        ("z", [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]),  # drone yawed +90: world x is base -y
        ("x", [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]),  # rolled +90: world y is base -z
        ("y", [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]),  # pitched +90: world z is base -x
    ],
)
def test_rotations_about_each_axis(axis, world, base):
    drone = Pose.from_arrays([0.0, 0.0, 0.0], _about(axis, 90.0))
    np.testing.assert_allclose(world_to_base(world, drone), base, atol=1e-15)
    np.testing.assert_allclose(base_to_world(base, drone), world, atol=1e-15)


def test_translation_and_mount():
    drone = Pose.from_arrays([1.0, 2.0, 3.0])
    np.testing.assert_allclose(world_to_base([1.0, 2.0, 2.0], drone), [0.0, 0.0, -1.0])
    # base 0.1 m below the drone's centre (thesis: frames shifted along z only)
    mount = Pose.from_arrays([0.0, 0.0, -0.1])
    np.testing.assert_allclose(world_to_base([1.0, 2.0, 2.7], drone, mount), [0.0, 0.0, -0.2])


def test_yawed_drone_with_offset_mount_by_hand():
    drone = Pose.from_arrays([0.5, 0.0, 1.0], [S, 0.0, 0.0, S])  # yaw +90
    mount = Pose.from_arrays([0.1, 0.0, -0.05])  # base ahead of and below the body centre
    # base origin in world: (0.5, 0, 1) + Rz90 (0.1, 0, -0.05) = (0.5, 0.1, 0.95)
    origin = base_to_world([0.0, 0.0, 0.0], drone, mount)
    np.testing.assert_allclose(origin, [0.5, 0.1, 0.95], atol=1e-15)
    # world point 0.2 m below the base origin and 0.1 along world +x: base (0, -0.1, -0.2)
    expected = [0.0, -0.1, -0.2]
    np.testing.assert_allclose(world_to_base([0.6, 0.1, 0.75], drone, mount), expected, atol=1e-15)


quaternions = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1
)


@pytest.mark.slow
@given(quaternions, quaternions, st.lists(st.floats(-2, 2), min_size=3, max_size=3))
def test_round_trip_and_agreement_with_scipy(q_drone, q_mount, point):
    drone = Pose.from_arrays([0.3, -0.2, 1.5], np.array(q_drone) / np.linalg.norm(q_drone))
    mount = Pose.from_arrays([0.0, 0.02, -0.1], np.array(q_mount) / np.linalg.norm(q_mount))
    base = world_to_base(point, drone, mount)
    np.testing.assert_allclose(base_to_world(base, drone, mount), point, atol=1e-12)
    w, x, y, z = drone.quaternion
    scipy_matrix = Rotation.from_quat([x, y, z, w]).as_matrix()  # scipy is scalar-last
    np.testing.assert_allclose(drone.rotation, scipy_matrix, atol=1e-12)
    identity = drone @ drone.inverse()
    np.testing.assert_allclose(identity.position, 0.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(identity.quaternion), [1, 0, 0, 0], atol=1e-12)


def test_batches_of_poses_broadcast():
    drone = Pose.from_arrays(np.zeros((4, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (4, 1)))
    points = np.arange(12.0).reshape(4, 3)
    np.testing.assert_allclose(world_to_base(points, drone), points)


@pytest.mark.parametrize(
    ("quaternion", "message"),
    [
        ([0.0, 0.0, 0.0, 0.0], "zero"),
        ([1.0, math.nan, 0.0, 0.0], "finite"),
        ([2.0, 0.0, 0.0, 0.0], "unit"),
        ([1.0, 0.0, 0.0], "shape"),
    ],
)
def test_bad_quaternions_are_rejected(quaternion, message):
    with pytest.raises((PoseError, ValueError), match=message):
        Pose.from_arrays([0.0, 0.0, 0.0], quaternion)


def test_small_drift_is_normalised_and_bad_positions_rejected():
    q = unit_quaternion([1.0 + 5e-4, 0.0, 0.0, 0.0])
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
    with pytest.raises(PoseError, match="position"):
        Pose.from_arrays([math.inf, 0.0, 0.0])

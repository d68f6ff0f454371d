"""ROS messages the robot node takes: frames (PX4's NED/FRD against the same drone in
ENU/FLU, by hand), stamps, goals, and bad bytes refused with a reason."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.robot.ros_inputs import (
    InputRefused,
    check_stamp,
    decode,
    goal_from,
    pose_from_odometry,
    pose_from_pose_stamped,
    pose_from_px4,
)
from app.ros2.messages import JOINT_STATE, ODOMETRY, POINT, POSE, PX4_ODOMETRY, typestore

STORE = typestore("jazzy")
T = STORE.types
WORLD = ("map", "odom", "world")
H = math.sqrt(0.5)


def _header(frame: str, stamp_s: float = 100.25):
    sec = math.floor(stamp_s)
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp_s - sec) * 1e9)),
        frame_id=frame,
    )


def _pose(xyz, wxyz):
    w, x, y, z = wxyz
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=xyz[0], y=xyz[1], z=xyz[2]),
        orientation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
    )


def _vector(xyz):
    return T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2])


def _odometry(frame="odom", xyz=(2.0, 1.0, 3.0), wxyz=(1.0, 0, 0, 0), v_body=(0, 0, 0)):
    twist = T["geometry_msgs/msg/Twist"](linear=_vector(v_body), angular=_vector((0, 0, 0.2)))
    return T[ODOMETRY](
        header=_header(frame),
        child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=_pose(xyz, wxyz), covariance=np.zeros(36)
        ),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )


def _px4(pose_frame=1, velocity_frame=1, q=(H, 0.0, 0.0, H), velocity=(1.0, 0.0, 0.0)):
    f32 = np.float32
    return T[PX4_ODOMETRY](
        timestamp=100_250_000,
        timestamp_sample=100_240_000,
        pose_frame=pose_frame,
        position=np.array([1.0, 2.0, -3.0], dtype=f32),  # 1 m north, 2 m east, 3 m up
        q=np.array(q, dtype=f32),  # FRD to NED: facing east (yaw 90 deg)
        velocity_frame=velocity_frame,
        velocity=np.array(velocity, dtype=f32),
        angular_velocity=np.array([0.0, 0.0, 0.2], dtype=f32),  # turning right (FRD z down)
        position_variance=np.zeros(3, dtype=f32),
        orientation_variance=np.zeros(3, dtype=f32),
        velocity_variance=np.zeros(3, dtype=f32),
        reset_counter=0,
        quality=0,
    )


def _through_cdr(message, typename):
    return decode(STORE, typename, bytes(STORE.serialize_cdr(message, typename)))


def test_px4_ned_frd_is_the_same_drone_as_enu_flu_by_hand() -> None:
    pose = pose_from_px4(_through_cdr(_px4(), PX4_ODOMETRY))
    assert pose.t_s == pytest.approx(100.25)
    assert pose.position_m == pytest.approx([2.0, 1.0, 3.0])  # east, north, up
    # facing east is ENU's yaw 0: the identity (up to sign)
    assert np.abs(pose.quaternion) == pytest.approx([1.0, 0, 0, 0], abs=1e-6)
    assert pose.velocity_m_s == pytest.approx([0.0, 1.0, 0.0])  # north is ENU's y
    assert pose.angular_velocity_rad_s == pytest.approx([0.0, 0.0, -0.2], abs=1e-7)
    # the same drone as an ENU odometry (FLU twist) gives the same pose
    odometry = pose_from_odometry(
        _through_cdr(_odometry(v_body=(0, 1.0, 0)), ODOMETRY), WORLD, "base_link"
    )
    assert odometry.position_m == pytest.approx(pose.position_m)
    assert odometry.velocity_m_s == pytest.approx(pose.velocity_m_s, abs=1e-6)


def test_a_body_velocity_is_turned_into_the_world() -> None:
    forward = pose_from_px4(_through_cdr(_px4(velocity_frame=3), PX4_ODOMETRY))
    assert forward.velocity_m_s == pytest.approx([1.0, 0.0, 0.0], abs=1e-6)  # east
    north = (H, 0.0, 0.0, H)  # ENU: yaw 90 deg, facing north
    odometry = pose_from_odometry(
        _through_cdr(_odometry(wxyz=north, v_body=(1.0, 0, 0)), ODOMETRY), WORLD, "base_link"
    )
    assert odometry.velocity_m_s == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)
    unknown = pose_from_px4(_through_cdr(_px4(velocity=(np.nan,) * 3), PX4_ODOMETRY))
    assert unknown.velocity_m_s is None  # PX4's NaN: not known, the tracker differences


@pytest.mark.parametrize(
    ("message", "key", "words"),
    [
        (_px4(pose_frame=2), "frame", "pose_frame"),
        (_px4(pose_frame=0), "frame", "pose_frame"),
        (_px4(q=(0.5, 0.5, 0.5, 0.0)), "value", "q"),
        (_px4(q=(np.nan, 0, 0, 1)), "value", "q"),
    ],
)
def test_px4_messages_it_cannot_use(message, key: str, words: str) -> None:
    with pytest.raises(InputRefused, match=words) as refused:
        pose_from_px4(_through_cdr(message, PX4_ODOMETRY))
    assert refused.value.key == key


def test_world_frames_and_values_are_checked() -> None:
    with pytest.raises(InputRefused, match="header.frame_id: 'base_link'") as refused:
        pose_from_odometry(_odometry(frame="base_link"), WORLD, "base_link")
    assert refused.value.key == "frame"
    with pytest.raises(InputRefused, match="position") as refused:
        pose_from_odometry(_odometry(xyz=(np.nan, 0, 0)), WORLD, "base_link")
    with pytest.raises(InputRefused, match="child_frame_id: 'base_link' is not the drone"):
        pose_from_odometry(_odometry(), WORLD, "drone")
    assert refused.value.key == "value"
    stamped = T[POSE](header=_header("map"), pose=_pose((1, 2, 3), (1, 0, 0, 0)))
    pose = pose_from_pose_stamped(_through_cdr(stamped, POSE), WORLD)
    assert pose.position_m.tolist() == [1, 2, 3] and pose.velocity_m_s is None


def test_stamps_from_the_future_or_too_old_are_refused() -> None:
    check_stamp(100.0, 100.02, future_s=0.05, age_s=0.5)
    for t, key in ((100.2, "future"), (99.0, "old"), (math.nan, "stamp")):
        with pytest.raises(InputRefused, match="header.stamp") as refused:
            check_stamp(t, 100.0, future_s=0.05, age_s=0.5)
        assert refused.value.key == key


def test_goals_in_the_base_or_the_world() -> None:
    yaw = 0.3
    turn = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    stamped = T[POSE](header=_header("delta_base"), pose=_pose((0.01, 0.02, -0.25), turn))
    goal = goal_from(_through_cdr(stamped, POSE), True, "delta_base", WORLD)
    assert goal.frame == "base" and goal.point_m.tolist() == [0.01, 0.02, -0.25]
    assert goal.phi_rad == pytest.approx(yaw)
    point = T[POINT](
        header=_header("world"), point=T["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.5)
    )
    goal = goal_from(_through_cdr(point, POINT), False, "delta_base", WORLD)
    assert goal.frame == "world" and goal.phi_rad is None
    tilted = T[POSE](header=_header("delta_base"), pose=_pose((0, 0, -0.25), (H, H, 0, 0)))
    with pytest.raises(InputRefused, match="only turns about z"):
        goal_from(tilted, True, "delta_base", WORLD)
    elsewhere = T[POSE](header=_header("camera"), pose=_pose((0, 0, -0.25), (1, 0, 0, 0)))
    with pytest.raises(InputRefused, match="'camera' is neither the base frame") as refused:
        goal_from(elsewhere, True, "delta_base", WORLD)
    assert refused.value.key == "frame"


def test_bytes_that_are_not_the_type_are_refused() -> None:
    good = bytes(STORE.serialize_cdr(_odometry(), ODOMETRY))
    joints = T[JOINT_STATE](
        header=_header(""),
        name=["a"],
        position=np.zeros(1),
        velocity=np.zeros(1),
        effort=np.zeros(0),
    )
    for payload in (good[: len(good) // 2], b"", b"\x00\x01\x00\x00", b"\xff" * 40):
        with pytest.raises(InputRefused, match="not a nav_msgs/msg/Odometry") as refused:
            decode(STORE, ODOMETRY, payload)
        assert refused.value.key == "cdr"
    wrong = bytes(STORE.serialize_cdr(joints, JOINT_STATE))
    with pytest.raises(InputRefused):  # too short for an odometry
        decode(STORE, ODOMETRY, wrong)


def test_with_a_token_ros_inputs_need_a_trusted_network() -> None:
    from pydantic import ValidationError

    from app.config import Settings

    token = {"token": "a-token-of-twenty-chars"}
    for inputs in ({"pose_input": "odometry"}, {"goal_input": "pose"}):
        with pytest.raises(ValidationError, match="carry no credentials"):
            Settings(server=token, ros2=inputs)
        Settings(server=token, ros2={**inputs, "inputs_trusted": True})
        Settings(ros2=inputs)  # no token: loopback by default, as the other pose inputs
    Settings(server=token)  # publishing needs no trust

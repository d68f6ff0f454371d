"""MAVLink ODOMETRY frames: the pose's frame_id and the velocity's child_frame_id, decoded
from pymavlink-encoded messages and checked against hand-computed ENU velocities."""

from __future__ import annotations

import itertools
import math
import socket

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from app.world.inputs import FrameRefused, MavlinkPoseListener, sample_from_odometry
from app.world.poses import PoseTracker
from tests.support.wait import wait_for

H = math.sqrt(0.5)
FACING_EAST = [H, 0.0, 0.0, H]  # NED/FRD attitude: yawed +90 deg about down
NAN21 = [float("nan")] * 21


def _encoded(frame_id, child_frame_id, velocity, q=FACING_EAST, t_us=1_000_000):
    """An ODOMETRY message packed by pymavlink and decoded again by a separate parser."""
    encoder = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    msg = encoder.odometry_encode(
        t_us, frame_id, child_frame_id, 1.0, 2.0, -3.0, q, *velocity, 0.0, 0.0, 0.0, NAN21, NAN21
    )
    return mavlink.MAVLink(None).decode(bytearray(msg.pack(encoder)))


def _velocity(frame_id, child_frame_id, velocity, q=FACING_EAST):
    return sample_from_odometry(_encoded(frame_id, child_frame_id, velocity, q)).velocity_m_s


def test_a_local_ned_velocity_is_an_earth_velocity_not_a_body_one() -> None:
    # facing east, flying north at 1 m/s, the velocity sent in LOCAL_NED (VOXL): world north
    v = _velocity(mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_NED, (1.0, 0.0, 0.0))
    np.testing.assert_allclose(v, [0.0, 1.0, 0.0], atol=1e-12)
    v = _velocity(mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_NED, (0.0, 2.0, 0.5))
    np.testing.assert_allclose(v, [2.0, 0.0, -0.5], atol=1e-12)  # east, sinking


def test_a_local_frd_pose_takes_a_local_frd_velocity() -> None:
    v = _velocity(mavlink.MAV_FRAME_LOCAL_FRD, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 0.0, -1.0))
    np.testing.assert_allclose(v, [0.0, 1.0, 1.0], atol=1e-12)


@pytest.mark.parametrize("child", [mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_BODY_NED])
def test_a_body_velocity_is_rotated_by_the_attitude(child) -> None:
    # facing east: forward is east, right is south, down is down
    v = _velocity(mavlink.MAV_FRAME_LOCAL_NED, child, (1.0, 0.0, 0.0))
    np.testing.assert_allclose(v, [1.0, 0.0, 0.0], atol=1e-12)
    v = _velocity(mavlink.MAV_FRAME_LOCAL_NED, child, (0.0, 1.0, 1.0))
    np.testing.assert_allclose(v, [0.0, -1.0, -1.0], atol=1e-12)
    # facing north, pitched 30 deg nose up: forward is (north cos 30, up sin 30)
    pitch = math.radians(30.0)
    q = [math.cos(pitch / 2), 0.0, math.sin(pitch / 2), 0.0]
    v = _velocity(mavlink.MAV_FRAME_LOCAL_NED, child, (2.0, 0.0, 0.0), q)
    np.testing.assert_allclose(v, [0.0, 2 * math.cos(pitch), 2 * math.sin(pitch)], atol=1e-12)


@pytest.mark.parametrize(
    ("frame", "child", "field"),
    [
        (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_ENU, "child_frame_id"),
        (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_GLOBAL, "child_frame_id"),
        (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_FLU, "child_frame_id"),
        # two earth frames whose relative heading is unknown
        (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_FRD, "child_frame_id"),
        (mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_BODY_FRD, "frame_id"),
        (mavlink.MAV_FRAME_LOCAL_ENU, mavlink.MAV_FRAME_BODY_FRD, "frame_id"),
        (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_BODY_FRD, "frame_id"),
    ],
)
def test_unsupported_frames_are_refused_by_name(frame, child, field) -> None:
    with pytest.raises(FrameRefused, match=field) as info:
        sample_from_odometry(_encoded(frame, child, (1.0, 0.0, 0.0)))
    assert info.value.field == field and "MAV_FRAME_" in info.value.key


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_refused_frames_are_counted_in_the_pose_input_status() -> None:
    tracker = PoseTracker(stale_after_s=0.05, lost_after_s=0.5, max_jump_m=0.5)
    port = _free_port()
    listener = MavlinkPoseListener(tracker, f"udpin:127.0.0.1:{port}").start()
    encoder = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    sent = itertools.count()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:

            def refused_seen() -> bool:
                msg = encoder.odometry_encode(
                    1_000_000 + 10_000 * next(sent),
                    mavlink.MAV_FRAME_LOCAL_NED,
                    mavlink.MAV_FRAME_LOCAL_ENU,
                    *(1.0, 2.0, -3.0),
                    FACING_EAST,
                    *(1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
                    NAN21,
                    NAN21,
                )
                sender.sendto(msg.pack(encoder), ("127.0.0.1", port))
                return (
                    tracker.status()["refused_frames"].get("child_frame_id MAV_FRAME_LOCAL_ENU", 0)
                    >= 2
                )

            wait_for(refused_seen, "LOCAL_ENU velocities refused and counted", 10, poll_s=0.05)
    finally:
        listener.stop()
    assert tracker.accepted == 0 and listener.errors >= 2

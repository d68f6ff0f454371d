"""Pose streams on loopback: UDP JSON, real MAVLink ODOMETRY through pymavlink, and the API."""

from __future__ import annotations

import itertools
import json
import socket
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from app.world.inputs import MavlinkPoseListener, UdpPoseListener
from app.world.poses import PoseTracker
from tests.support.wait import wait_for


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture
def tracker() -> PoseTracker:
    return PoseTracker(stale_after_s=0.05, lost_after_s=0.5, max_jump_m=0.5)


def test_udp_json_stream_is_received_and_vetted(tracker):
    listener = UdpPoseListener(tracker, _free_port()).start()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            for k in range(5):
                sample = {
                    "t": 0.01 * k,
                    "position": [0.0, 0.0, 1.0 + 0.001 * k],
                    "quaternion": [1, 0, 0, 0],
                }
                sender.sendto(json.dumps(sample).encode(), ("127.0.0.1", listener.port))
            sender.sendto(
                b'{"t": 1, "position": [0, 0], "quaternion": [1,0,0,0]}',
                ("127.0.0.1", listener.port),
            )
            sender.sendto(b"not json", ("127.0.0.1", listener.port))
        wait_for(lambda: tracker.accepted == 5 and listener.errors == 2, "five good, two bad")
    finally:
        listener.stop()
    sample, _ = tracker.latest()
    np.testing.assert_allclose(sample.position_m, [0.0, 0.0, 1.004])


@pytest.mark.slow
def test_udp_platform_marker_poses_go_to_their_own_tracker(tracker):
    platform = PoseTracker(stale_after_s=0.05, lost_after_s=0.5, max_jump_m=0.5)
    listener = UdpPoseListener(tracker, _free_port(), platform=platform).start()
    alone = UdpPoseListener(PoseTracker(0.05, 0.5, 0.5), _free_port()).start()
    marker = {"t": 1.0, "position": [0.01, 0.02, -0.3], "quaternion": [1, 0, 0, 0]}
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            for port, sample in (
                (listener.port, {**marker, "body": "platform"}),
                (listener.port, {**marker, "t": 2.0}),  # no body: the drone's
                (listener.port, {**marker, "t": 3.0, "body": "tool"}),
                (alone.port, {**marker, "body": "platform"}),  # nowhere to go: an error
            ):
                sender.sendto(json.dumps(sample).encode(), ("127.0.0.1", port))
        wait_for(
            lambda: platform.accepted == 1 and tracker.accepted == 1 and listener.errors == 1,
            "one marker pose, one drone pose, one bad body",
        )
        wait_for(lambda: alone.errors == 1, "the marker pose refused without a tracker")
    finally:
        listener.stop()
        alone.stop()
    assert platform.latest()[0].t_s == 1.0 and tracker.latest()[0].t_s == 2.0


def test_mavlink_odometry_is_converted_from_ned(tracker):
    port = _free_port()
    listener = MavlinkPoseListener(tracker, f"udpin:127.0.0.1:{port}").start()
    h = np.sqrt(0.5)
    encoder = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:

            def send(k: int) -> None:
                msg = encoder.odometry_encode(
                    1_000_000 + 10_000 * k,
                    mavlink.MAV_FRAME_LOCAL_NED,
                    mavlink.MAV_FRAME_BODY_FRD,
                    1.0,
                    2.0,
                    -3.0,
                    [h, 0.0, 0.0, h],  # 3 m up, yawed to face east
                    0.5,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.1,
                    [float("nan")] * 21,
                    [float("nan")] * 21,
                )
                sender.sendto(msg.pack(encoder), ("127.0.0.1", port))

            sent = itertools.count()

            def accepted() -> bool:
                send(next(sent))
                return tracker.accepted > 0

            wait_for(accepted, "an ODOMETRY message accepted by the tracker", 10, poll_s=0.05)
    finally:
        listener.stop()
    sample, velocity = tracker.latest()
    assert sample is not None, "no ODOMETRY arrived"
    np.testing.assert_allclose(sample.position_m, [2.0, 1.0, 3.0])  # east, north, up
    np.testing.assert_allclose(sample.pose.rotation @ [1, 0, 0], [1, 0, 0], atol=1e-9)
    np.testing.assert_allclose(velocity, [0.5, 0.0, 0.0], atol=1e-9)  # forward = east
    np.testing.assert_allclose(sample.angular_velocity_rad_s, [0, 0, -0.1])  # FRD yaw -> FLU


def _good(t: float) -> bytes:
    return json.dumps({"t": t, "position": [0.0, 0.0, 1.0], "quaternion": [1, 0, 0, 0]}).encode()


@pytest.mark.parametrize(
    ("poison", "reason"),
    [
        (b'{"t": ' + b"9" * 400 + b', "position": [0, 0, 1], "quaternion": [1, 0, 0, 0]}', "large"),
        (b"[" * 30_000 + b"]" * 30_000, "deep"),
        (b'{"t": 1, "position": [' + b"9" * 400 + b', 0, 1], "quaternion": [1, 0, 0, 0]}', "large"),
    ],
    ids=["huge-t", "deep-array", "huge-position"],
)
def test_udp_listener_survives_a_poison_datagram_and_names_it(tracker, poison, reason):
    listener = UdpPoseListener(tracker, _free_port()).start()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.sendto(poison, ("127.0.0.1", listener.port))
            wait_for(lambda: listener.errors == 1, "the poison datagram counted")
            sender.sendto(_good(1.0), ("127.0.0.1", listener.port))
            wait_for(lambda: tracker.accepted == 1, "a good datagram after the poison one")
        status = listener.status()
        assert status["alive"] is True and status["errors"] == 1
        assert reason in status["last_error"]
    finally:
        listener.stop()


@pytest.mark.slow
def test_a_dead_udp_listener_says_so_and_restarts(tracker):
    listener = UdpPoseListener(tracker, _free_port()).start()
    try:
        listener.socket.close()  # a socket error: the thread cannot go on
        wait_for(lambda: not listener.status()["alive"], "the listener seen dead")
        assert listener.status()["last_error"]
        listener.restart()
        assert listener.status()["alive"] is True and listener.status()["restarts"] == 1
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.sendto(_good(1.0), ("127.0.0.1", listener.port))
        wait_for(lambda: tracker.accepted == 1, "a datagram accepted after the restart")
    finally:
        listener.stop()


TOKEN = "s3cret-token"


@pytest.mark.slow
def test_with_a_token_set_udp_poses_carry_it_or_are_refused(tracker):
    listener = UdpPoseListener(tracker, _free_port(), token=TOKEN).start()
    trusted = UdpPoseListener(PoseTracker(0.05, 0.5, 0.5), _free_port(), token=TOKEN, trusted=True)
    trusted.start()
    pose = {"position": [0.0, 0.0, 1.0], "quaternion": [1, 0, 0, 0]}
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            for sample in (
                {**pose, "t": 1.0},  # no token
                {**pose, "t": 2.0, "token": "wrong-token"},
                {**pose, "t": 3.0, "token": 12345678},
                {**pose, "t": 4.0, "token": TOKEN},
            ):
                sender.sendto(json.dumps(sample).encode(), ("127.0.0.1", listener.port))
            sender.sendto(_good(1.0), ("127.0.0.1", trusted.port))
        wait_for(lambda: listener.refused == 3 and tracker.accepted == 1, "three refused, one in")
        wait_for(lambda: trusted.tracker.accepted == 1, "the trusted bridge's pose, no token")
    finally:
        listener.stop()
        trusted.stop()
    assert tracker.latest()[0].t_s == 4.0
    status = listener.status()
    assert status["rule"] == "token" and "token" in status["last_error"]
    assert trusted.status()["rule"] == "trusted"
    assert UdpPoseListener(tracker, 0).status()["rule"] == "open"  # no token: as before


def _odometry(encoder, k: int):
    return encoder.odometry_encode(
        1_000_000 + 10_000 * k,
        mavlink.MAV_FRAME_LOCAL_NED,
        mavlink.MAV_FRAME_BODY_FRD,
        *(0.0, 0.0, -1.0),
        [1.0, 0.0, 0.0, 0.0],
        *([0.0] * 6),
        [float("nan")] * 21,
        [float("nan")] * 21,
    ).pack(encoder)


def test_with_a_token_set_mavlink_is_refused_unless_trusted(tracker):
    port = _free_port()
    listener = MavlinkPoseListener(tracker, f"udpin:127.0.0.1:{port}", token=TOKEN).start()
    encoder = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    sent = itertools.count()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:

            def refused() -> bool:
                sender.sendto(_odometry(encoder, next(sent)), ("127.0.0.1", port))
                return listener.refused >= 3

            wait_for(refused, "ODOMETRY refused and counted", 10, poll_s=0.05)
    finally:
        listener.stop()
    assert tracker.accepted == 0 and listener.status()["rule"] == "refused"
    assert "neither signed nor trusted" in listener.status()["last_error"]
    trusted = MavlinkPoseListener(tracker, "udpin:127.0.0.1:0", token=TOKEN, trusted=True)
    trusted.stop()
    assert trusted.status()["rule"] == "trusted"


def test_a_signing_key_takes_signed_mavlink_and_refuses_the_rest(tracker):
    key = bytes(range(32))
    port = _free_port()
    listener = MavlinkPoseListener(
        tracker, f"udpin:127.0.0.1:{port}", token=TOKEN, signing_key=key
    ).start()
    unsigned = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    signed = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    signed.signing.secret_key, signed.signing.sign_outgoing = key, True
    now = int((time.time() - 1420070400) * 100_000)  # MAVLink2: 10 us units since 2015
    signed.signing.link_id, signed.signing.timestamp = 1, now
    wrong = mavlink.MAVLink(None, srcSystem=2, srcComponent=1)
    wrong.signing.secret_key, wrong.signing.sign_outgoing = bytes(32), True
    wrong.signing.link_id, wrong.signing.timestamp = 1, now
    sent = itertools.count()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:

            def refused() -> bool:
                k = next(sent)
                sender.sendto(_odometry(unsigned, k), ("127.0.0.1", port))
                sender.sendto(_odometry(wrong, k), ("127.0.0.1", port))
                return listener.refused >= 4

            wait_for(refused, "unsigned and wrongly signed ODOMETRY refused", 10, poll_s=0.05)
            assert tracker.accepted == 0

            def accepted() -> bool:
                sender.sendto(_odometry(signed, 100 + next(sent)), ("127.0.0.1", port))
                return tracker.accepted > 0

            wait_for(accepted, "signed ODOMETRY accepted", 10, poll_s=0.05)
    finally:
        listener.stop()
    assert listener.status()["rule"] == "signed" and "sign" in listener.status()["last_error"]

"""The simulated drone as a pose input (app/world/drone_feed.py), on simulated time: what it
pushes is the drone's own measurement, once per measurement, and a failing push is counted."""

from __future__ import annotations

import numpy as np
import pytest

from app.world.drone_feed import DroneFeed, pose_message
from app.world.drone_sim import DroneSimParams, SimulatedDrone
from app.world.inputs import sample_from_json
from app.world.poses import PoseTracker
from kinematics import PoseError


def test_each_push_is_the_drones_measurement_once_and_the_tracker_names_its_source():
    params = DroneSimParams(seed=7, rate_hz=50.0, latency_s=0.02)
    tracker = PoseTracker(stale_after_s=0.05, lost_after_s=0.5, max_jump_m=0.05)
    pushed: list[dict] = []

    def push(message: dict) -> None:
        pushed.append(message)
        tracker.push(sample_from_json(message))

    feed = DroneFeed(push, params)
    drone = SimulatedDrone(params)
    times = 100.0 + np.arange(0.0, 1.0, 0.005)  # 200 Hz asks of a 50 Hz drone
    for t in times:
        feed.step(float(t))
    # one push per measurement period covered: 1 s at 50 Hz (the first stamp included)
    stamps = [m["t"] for m in pushed]
    assert len(stamps) == len(set(stamps)) and 50 <= len(stamps) <= 51
    np.testing.assert_allclose(np.diff(stamps), 1 / 50, atol=1e-9)
    stamp, pose, velocity = drone.measured(float(times[-1]))
    assert pushed[-1]["t"] == stamp
    np.testing.assert_allclose(pushed[-1]["position"], pose.position, atol=1e-12)
    np.testing.assert_allclose(pushed[-1]["quaternion"], pose.quaternion, atol=1e-12)
    np.testing.assert_allclose(pushed[-1]["velocity"], velocity, atol=1e-12)
    status = tracker.status()
    assert status["source"] == "simulated" and status["accepted"] == len(pushed)
    np.testing.assert_allclose(status["position_m"], pose.position, atol=1e-12)
    assert status["rate_hz"] == pytest.approx(50.0, rel=1e-6)
    assert feed.status()["sent"] == len(pushed)


def test_a_failing_push_is_counted_and_said():
    def push(message: dict) -> None:
        raise ConnectionError("node offline")

    feed = DroneFeed(push, DroneSimParams())
    assert feed.step(10.0) is False
    assert feed.failures == 1 and "node offline" in feed.last_error and feed.sent == 0


def test_a_message_names_its_source_and_a_client_cannot_name_another():
    _, message = pose_message(SimulatedDrone(), 3.0)
    assert sample_from_json(message).source == "simulated"
    with pytest.raises(PoseError, match="source"):
        sample_from_json({**message, "source": "moon"})

"""The tool's world heading and the wrist angle that keeps it (app/world/heading.py), and
the hold source commanding it (app/world/hold.py): laws, no timing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.config import load_settings
from app.control.commands import CommandContext
from app.world.heading import fit_to_limits, tool_heading, wrap, wrist_angle
from app.world.hold import HoldSource, Observation
from kinematics import Pose
from kinematics.pose import quaternion_multiply

RNG = np.random.default_rng(19)


def _turn(axis, angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])


def _attitude(roll: float, pitch: float, yaw: float) -> np.ndarray:
    q = quaternion_multiply(_turn((0, 0, 1), yaw), _turn((0, 1, 0), pitch))
    return quaternion_multiply(q, _turn((1, 0, 0), roll))


def test_level_base_heading_is_yaw_plus_phi():
    for _ in range(20):
        yaw, phi = RNG.uniform(-math.pi, math.pi, 2)
        rotation = Pose(np.zeros(3), _turn((0, 0, 1), yaw)).rotation
        assert wrap(tool_heading(rotation, phi) - (yaw + phi)) == pytest.approx(0.0, abs=1e-12)
        assert wrap(wrist_angle(rotation, yaw + phi) - phi) == pytest.approx(0.0, abs=1e-12)


def test_wrist_angle_inverts_heading_on_a_tilted_base():
    for _ in range(50):
        roll, pitch = RNG.uniform(-0.35, 0.35, 2)  # up to 20 deg of tilt
        yaw, heading = RNG.uniform(-math.pi, math.pi, 2)
        rotation = Pose(np.zeros(3), _attitude(roll, pitch, yaw)).rotation
        phi = wrist_angle(rotation, heading)
        assert wrap(tool_heading(rotation, phi) - heading) == pytest.approx(0.0, abs=1e-9)


def test_fit_to_limits_moves_by_turns_or_holds_the_nearest_limit():
    assert fit_to_limits(3.0, -1.0, 3.5, 0.0) == (pytest.approx(3.0), False)
    # 3.0 - 2 pi = -3.28 is the same angle; inside [-3.5, 1]
    assert fit_to_limits(3.0, -3.5, 1.0, 0.0) == (pytest.approx(3.0 - 2 * math.pi), False)
    # two fit: the one nearer the wrist
    phi, limited = fit_to_limits(-3.0, -3.2, 3.4, 2.0)
    assert phi == pytest.approx(-3.0 + 2 * math.pi) and not limited
    # none fits: the limit nearest round the circle
    assert fit_to_limits(2.0, -1.0, 1.0, 0.0) == (1.0, True)
    assert fit_to_limits(-2.0, -1.0, 1.0, 0.0) == (-1.0, True)
    assert fit_to_limits(2.9, -1.0, 0.2, 0.0) == (-1.0, True)  # 2.9 rad: -1 is nearer via pi


class _YawingDrone:
    """A drone at a fixed place, yawing (and optionally rolling) as a sine; fresh poses."""

    def __init__(self, yaw_amplitude: float, roll: float = 0.0) -> None:
        self.amplitude, self.roll = yaw_amplitude, roll

    def yaw(self, t: float) -> float:
        return self.amplitude * math.sin(2 * math.pi * 0.7 * t)

    def pose(self, t: float) -> Pose:
        return Pose(np.array([0.0, 0.0, 1.5]), _attitude(self.roll, 0.0, self.yaw(t)))

    def observe(self, t: float) -> Observation:
        return Observation("ok", 0.0, self.pose(t), np.zeros(3), np.zeros(3))

    def true_pose(self, t: float) -> Pose:
        return self.pose(t)


def _gate(wrist: bool):
    sections = {"tool": {"offset_m": (0.0, 0.0, -0.05)}}
    if wrist:
        sections["wrist"] = {"enabled": True, "min_angle_rad": -1.0, "max_angle_rad": 1.0}
    return CommandContext.from_settings(load_settings(**sections)).gate


def _source(drone, gate, heading=None, wrist=True):
    mount = Pose.from_arrays((0.0, 0.0, -0.08))
    goal = drone.pose(0.0) @ mount
    here = np.array([0.0, 0.0, -0.29])  # a tip under the platform
    return HoldSource(
        goal.apply(here),
        drone,
        mount,
        gate,
        lambda: here,
        None,
        wrist=(gate.wrist_min_rad, gate.wrist_max_rad) if wrist else None,
        measured_phi=lambda: 0.0,
        heading_rad=heading,
    )


@pytest.mark.slow
@pytest.mark.parametrize("roll", [0.0, 0.2])
def test_hold_commands_phi_plus_yaw_equal_to_the_world_heading(roll):
    drone = _YawingDrone(0.5, roll)
    source = _source(drone, _gate(wrist=True))
    mount = Pose.from_arrays((0.0, 0.0, -0.08))
    dt, seen = 0.005, []
    for _ in range(600):
        setpoint = source.next(dt)
        if source.t_s < source.approach_s:
            continue
        base = (drone.pose(source.t_s) @ mount).rotation
        assert tool_heading(base, setpoint.phi_rad) == pytest.approx(source.heading, abs=1e-9)
        if roll == 0.0:  # level: phi = heading - yaw
            assert wrap(setpoint.phi_rad + drone.yaw(source.t_s) - source.heading) == (
                pytest.approx(0.0, abs=1e-9)
            )
        assert not setpoint.extra["heading_limited"]
        seen.append(setpoint.phi_rad)
    assert np.ptp(seen) > 0.8  # the wrist really turned against the yaw
    first = (drone.pose(dt) @ mount).rotation  # the heading at the first pose seen
    assert source.heading == pytest.approx(tool_heading(first, 0.0), abs=1e-12)


@pytest.mark.slow
def test_hold_past_the_wrist_limits_holds_the_limit_and_says_so():
    drone = _YawingDrone(1.4)  # the heading needs up to 1.4 rad; the wrist reaches 1
    source = _source(drone, _gate(wrist=True), heading=0.0)
    limited = []
    for _ in range(600):
        setpoint = source.next(0.005)
        assert -1.0 <= setpoint.phi_rad <= 1.0
        if source.t_s >= source.approach_s:
            limited.append(setpoint.extra["heading_limited"])
            if setpoint.extra["heading_limited"]:
                assert abs(setpoint.phi_rad) == 1.0
    assert any(limited) and not all(limited)


@pytest.mark.slow
def test_without_a_wrist_the_hold_sends_no_phi_and_no_heading():
    source = _source(_YawingDrone(0.5), _gate(wrist=False), wrist=False)
    for _ in range(300):
        setpoint = source.next(0.005)
        assert setpoint.phi_rad is None
        assert set(setpoint.extra) == {
            "goal_world_m",
            "measured_world_m",
            "measured_world_from",
            "outside",
            "pose_age_s",
            "drone_pose",
        }


def test_telemetry_world_frame_gives_the_wrapped_heading_error():
    from app.control.state import Snapshot
    from app.server.api import serialize
    from app.server.api.responses import WorldFrame

    extra = {
        "goal_world_m": [1.0, 2.0, 3.0],
        "measured_world_m": [1.0, 2.0, 3.0],
        "heading_world_rad": 3.1,
        "measured_heading_world_rad": -3.1,  # 0.08 rad short of a half turn the other way
        "heading_limited": False,
    }
    frame = WorldFrame.model_validate(serialize.world_frame(Snapshot(tick=1, extra=extra)))
    assert frame.heading_rad == 3.1 and frame.heading_limited is False
    assert frame.heading_error_rad == pytest.approx(6.2 - 2 * math.pi)
    plain = serialize.world_frame(Snapshot(tick=1, extra={**extra, "heading_world_rad": None}))
    assert "heading_rad" not in plain  # no wrist: the frame as before

"""An applied calibration written into the config file and read back at start
(app/calibration/procedure.py ``write_calibration``, app/config.py ``[robot.legs]``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.calibration.procedure import write_calibration
from app.config import load_settings
from hardware.encoder import RAD_PER_TICK
from kinematics import THESIS_DELTA, PerLegRotaryDelta, RotaryDelta
from tests.support.strategies import per_leg_deltas

ZERO = (0.0, 0.0, 0.0)
CONFIG = """\
[server]
http_port = 8123

[robot]
l = 0.2431

[[hardware.joints]]
servo_id = 1
zero_offset_ticks = 2000
gains = { p = 900 }

[[hardware.joints]]
servo_id = 2

[[hardware.joints]]
servo_id = 3
direction = -1
"""


@pytest.mark.slow
@settings(max_examples=25, deadline=None)
@given(robot=per_leg_deltas(), offsets=st.lists(st.floats(-0.2, 0.2), min_size=3, max_size=3))
def test_the_config_written_and_read_back_gives_the_same_robot(tmp_path_factory, robot, offsets):
    path = tmp_path_factory.mktemp("config") / "robot.toml"
    path.write_text(CONFIG)
    before = load_settings(path)
    joints = [joint.calibration() for joint in before.hardware.joints]
    applied = robot.with_values(joint_offsets_rad=ZERO)  # offsets live in the zero ticks
    write_calibration(path, joints, offsets, applied)
    after = load_settings(path)
    assert after.robot.build() == applied  # bit for bit: every length and angle
    # everything else kept: other sections, [robot]'s drawing, a joint's gains
    assert after.server.http_port == 8123 and after.robot.l == 0.2431
    assert after.hardware.joints[0].gains is not None and after.hardware.joints[0].gains.p == 900
    for old, new, offset in zip(joints, after.hardware.joints, offsets, strict=True):
        got = new.calibration().to_rad(1500) - old.to_rad(1500)
        assert math.isclose(got, offset, abs_tol=RAD_PER_TICK / 2 + 1e-12)


def test_an_offsets_fit_writes_no_legs(tmp_path):
    """The symmetric case: offsets alone leave the robot symmetric in the file too."""
    path = tmp_path / "robot.toml"
    path.write_text(CONFIG)
    joints = [joint.calibration() for joint in load_settings(path).hardware.joints]
    write_calibration(path, joints, np.radians([1.0, -2.0, 0.5]))
    assert "legs" not in path.read_text()
    robot = load_settings(path).robot.build()
    assert type(robot) is RotaryDelta and robot == RotaryDelta(0.1558, 0.2431, 0.0844, 0.038)


def test_a_second_geometry_replaces_the_first(tmp_path):
    path = tmp_path / "robot.toml"
    joints = [joint.calibration() for joint in load_settings().hardware.joints]
    first = PerLegRotaryDelta.from_symmetric(THESIS_DELTA, l=(0.2440, 0.2425, 0.2430))
    second = first.with_values(L=(0.1560, 0.1555, 0.1558))
    write_calibration(path, joints, ZERO, first)
    write_calibration(path, joints, ZERO, second)
    assert load_settings(path).robot.build() == second

"""Joint calibration: tick <-> rad, homing, and the TOML record."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardware.calibration import (
    JointCalibration,
    guided_homing,
    home,
    load,
    save,
)
from hardware.dynamixel.control_table import RAD_PER_TICK
from hardware.errors import CalibrationError
from hardware.homing import home_bus

calibrations = st.builds(
    JointCalibration,
    servo_id=st.integers(0, 252),
    zero_offset_ticks=st.integers(0, 4095),
    direction=st.sampled_from([1, -1]),
)


@given(calibrations, st.integers(0, 4095))
def test_ticks_to_rad_to_ticks_is_exact(cal: JointCalibration, ticks: int) -> None:
    assert cal.to_ticks(cal.to_rad(ticks)) == ticks


@given(calibrations, st.floats(-3.0, 3.0))
def test_rad_to_ticks_to_rad_within_half_a_tick(cal: JointCalibration, theta: float) -> None:
    assert abs(cal.to_rad(cal.to_ticks(theta)) - theta) <= RAD_PER_TICK / 2 + 1e-12


def test_direction_and_offset() -> None:
    forward = JointCalibration(1, zero_offset_ticks=2048, direction=1)
    backward = JointCalibration(1, zero_offset_ticks=2048, direction=-1)
    assert forward.to_ticks(math.pi / 2) == 3072
    assert backward.to_ticks(math.pi / 2) == 1024
    assert forward.to_rad(1024) == pytest.approx(-math.pi / 2)
    assert backward.tick_limits() == (1024, 3072)


@given(st.lists(calibrations, min_size=1, max_size=4, unique_by=lambda c: c.servo_id), st.data())
def test_homing_makes_the_held_pose_read_the_known_angles(cals, data) -> None:
    present = {c.servo_id: data.draw(st.integers(0, 4095)) for c in cals}
    known = data.draw(st.lists(st.floats(-1.0, 1.0), min_size=len(cals), max_size=len(cals)))
    homed = home(cals, present, known)
    for cal, new, theta in zip(cals, homed, known, strict=True):
        assert abs(new.to_rad(present[cal.servo_id]) - theta) <= RAD_PER_TICK / 2 + 1e-12
        assert (new.direction, new.min_angle_rad, new.max_angle_rad) == (
            cal.direction,
            cal.min_angle_rad,
            cal.max_angle_rad,
        )


def test_homing_refuses_missing_servos_and_mismatched_angles() -> None:
    cals = [JointCalibration(1), JointCalibration(2)]
    with pytest.raises(CalibrationError, match="servo 2"):
        home(cals, {1: 100})
    with pytest.raises(CalibrationError, match="3 known angles for 2 joints"):
        home(cals, {1: 100, 2: 200}, [0.0, 0.0, 0.0])


def test_guided_homing_prompts_then_reads() -> None:
    prompts: list[str] = []
    cals = [JointCalibration(1), JointCalibration(2, direction=-1)]
    homed = guided_homing(cals, lambda: {1: 1000, 2: 3000}, 0.0, confirm=prompts.append)
    assert len(prompts) == 1 and "homing pose" in prompts[0]
    assert [c.zero_offset_ticks for c in homed] == [1000, 3000]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"servo_id": 300}, "servo_id 300"),
        ({"servo_id": 1, "direction": 2}, "direction 2"),
        ({"servo_id": 1, "min_angle_rad": 1.0, "max_angle_rad": 0.5}, "min_angle_rad"),
    ],
)
def test_invalid_records_name_the_value(kwargs: dict, message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        JointCalibration(**kwargs)


def test_save_and_load_keep_other_sections(tmp_path: Path) -> None:
    path = tmp_path / "deltadash.toml"
    path.write_text('[app]\nport = 8080\n\n[hardware]\nport = "/dev/ttyUSB0"\n')
    cals = (JointCalibration(1, 1000, 1, -0.5, 1.2), JointCalibration(2, 3000, -1))
    save(path, cals)
    assert load(path) == cals
    config = tomllib.loads(path.read_text())
    assert config["app"] == {"port": 8080}
    assert config["hardware"]["port"] == "/dev/ttyUSB0"


def test_load_refuses_a_config_without_joints(tmp_path: Path) -> None:
    path = tmp_path / "empty.toml"
    path.write_text("[hardware]\n")
    with pytest.raises(CalibrationError, match="no \\[\\[hardware.joints\\]\\]"):
        load(path)
    path.write_text("[[hardware.joints]]\nservo_id = 1\ncolour = 'red'\n")
    with pytest.raises(CalibrationError, match="bad"):
        load(path)


def test_home_bus_saves_offsets_that_read_zero(bus, emulator, tmp_path: Path) -> None:
    # default limits +-pi/2 rad = +-1024 ticks: each range lies inside 0 .. 4095
    emulator.place({1: 1100, 2: 2000, 3: 3000})
    path = tmp_path / "deltadash.toml"
    homed = home_bus(bus, path, 0.0, confirm=lambda prompt: None)
    assert [c.zero_offset_ticks for c in homed] == [1100, 2000, 3000]
    assert load(path) == homed
    assert bus.read_state().position_rad.tolist() == [0.0, 0.0, 0.0]

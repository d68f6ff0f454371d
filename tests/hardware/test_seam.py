"""The encoder's seam (hardware/seam.py): what each operating mode reaches, and the fixes.

Hand-derived ticks for the limits used throughout, -0.6 .. 1.4 rad, at 4096 ticks a turn:
0.6 * 4096 / (2 pi) = 391.06 -> 391 ticks and 1.4 * 4096 / (2 pi) = 912.68 -> 913 ticks.
So with direction +1 a zero offset z gives the range z - 391 .. z + 913, inside 0 .. 4095
for 391 <= z <= 3182; with direction -1 it is z - 913 .. z + 391, inside for 913 <= z <= 3704.
"""

from __future__ import annotations

import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardware.bus import OperatingMode
from hardware.calibration import JointCalibration
from hardware.errors import CalibrationError
from hardware.seam import (
    SeamError,
    ServoSetup,
    check_joint,
    single_turn,
    turn_correction,
    zero_offsets_within,
)

POSITION = ServoSetup(OperatingMode.POSITION)
EXTENDED = ServoSetup(OperatingMode.EXTENDED_POSITION)


def joint(zero: int, direction: int = 1) -> JointCalibration:
    return JointCalibration(1, zero, direction, -0.6, 1.4)


@pytest.mark.parametrize(
    ("raw", "direction", "ticks", "crosses"),
    [
        (4000, 1, (3609, 4913), True),  # the issue's homing: past 4095
        (100, 1, (-291, 1013), True),  # below 0
        (2048, 1, (1657, 2961), False),
        (391, 1, (0, 1304), False),  # the lowest zero that fits
        (390, 1, (-1, 1303), True),
        (3182, 1, (2791, 4095), False),  # the highest
        (3183, 1, (2792, 4096), True),
        (4000, -1, (3087, 4391), True),
        (100, -1, (-813, 491), True),
        (3500, -1, (2587, 3891), False),
        (913, -1, (0, 1304), False),
        (912, -1, (-1, 1303), True),
        (3704, -1, (2791, 4095), False),
        (3705, -1, (2792, 4096), True),
    ],
)
def test_position_mode_refuses_ranges_across_the_seam(raw, direction, ticks, crosses) -> None:
    cal = joint(raw, direction)
    assert cal.tick_limits() == ticks
    if not crosses:
        check_joint(cal, POSITION, 2)
        return
    with pytest.raises(SeamError) as info:
        check_joint(cal, POSITION, 2)
    message = str(info.value)
    assert "servo 1 (joint 2)" in message and f"{ticks[0]} .. {ticks[1]} ticks" in message
    assert "seam" in message and "Operating Mode (11) = 4" in message
    check_joint(cal, EXTENDED, 2)  # a multi-turn servo turns through the seam


def test_the_fix_for_the_issues_homing_names_the_turns_and_the_zero_window() -> None:
    # z = 4000 must come to 391 .. 3182: down by 4000 - 3182 = 818 at least (to 391, 3609
    # at most), or up through the seam by 4096 + 391 - 4000 = 487 (to 4096 + 3182, 3278).
    with pytest.raises(SeamError) as info:
        check_joint(joint(4000), POSITION, 1)
    message = str(info.value)
    assert "-818 .. -3609 ticks" in message and "+487 .. +3278 ticks" in message
    assert "reads within 391 .. 3182 ticks (it reads 4000" in message
    assert "Homing Offset (20) =" not in message  # it cannot move the seam


@given(st.integers(0, 4095), st.sampled_from([1, -1]))
def test_every_suggested_turn_makes_the_range_fit_and_the_nearest_are_tight(zero, direction):
    cal = joint(zero, direction)
    try:
        check_joint(cal, POSITION, 1)
        return
    except SeamError as exc:
        spans = re.findall(r"([+-]\d+) \.\. ([+-]\d+) ticks \(", str(exc))
    assert spans
    for near, far in ((int(a), int(b)) for a, b in spans):
        step = 1 if near > 0 else -1
        for turn in (near, far, (near + far) // 2):  # the shaft reads modulo one turn
            check_joint(joint((zero + turn) % 4096, direction), POSITION, 1)
        for turn in (near - step, far + step):
            with pytest.raises(SeamError):
                check_joint(joint((zero + turn) % 4096, direction), POSITION, 1)


def test_zero_window_is_where_the_range_just_fits() -> None:
    assert zero_offsets_within(joint(0), (0, 4095)) == (391, 3182)
    assert zero_offsets_within(joint(0, -1), (0, 4095)) == (913, 3704)
    assert zero_offsets_within(joint(0), (0, 1000)) is None  # 1304 ticks do not fit in 1001


def test_a_homing_offset_narrows_position_mode_and_zero_restores_it() -> None:
    # Present = one-turn shaft + H: H = 500 leaves 500 .. 4095 (goals stop at 4095).
    narrowed = ServoSetup(OperatingMode.POSITION, homing_offset=500)
    assert narrowed.reachable() == (500, 4095)
    assert ServoSetup(OperatingMode.POSITION, homing_offset=-512).reachable() == (0, 3583)
    # zero 3400 with H = 500: present 3009 .. 4313, the shaft at 2509 .. 3813 (one turn)
    with pytest.raises(SeamError) as info:
        check_joint(joint(3400), narrowed, 3)
    message = str(info.value)
    assert "3009 .. 4313" in message and "Homing Offset (20) = 0 on servo 1" in message
    assert "crosses" not in message
    check_joint(joint(3400 - 500), POSITION, 3)  # the same shaft with H = 0: it fits


def test_position_mode_ignores_an_offset_beyond_1024() -> None:
    assert ServoSetup(OperatingMode.POSITION, homing_offset=1024).reachable() == (1024, 4095)
    assert ServoSetup(OperatingMode.POSITION, homing_offset=1025).offset_in_force == 0
    assert ServoSetup(OperatingMode.POSITION, homing_offset=-2000).reachable() == (0, 4095)
    assert ServoSetup(OperatingMode.EXTENDED_POSITION, homing_offset=-2000).offset_in_force == (
        -2000
    )


def test_goal_bounds_per_mode() -> None:
    assert ServoSetup(OperatingMode.POSITION, 0, 100, 2000).goal_bounds() == (100, 2000)
    assert EXTENDED.goal_bounds() == (-1_048_575, 1_048_575)
    assert EXTENDED.reachable() is None


@given(st.integers(-100_000, 100_000), st.integers(-1024, 1024))
def test_single_turn_is_the_same_shaft_within_one_turn(ticks: int, offset: int) -> None:
    value = single_turn(ticks, offset)
    assert offset <= value <= offset + 4095 and (value - ticks) % 4096 == 0


@given(st.integers(0, 4095), st.sampled_from([1, -1]), st.integers(-6, 6), st.data())
def test_turn_correction_brings_any_reading_of_the_range_onto_it(zero, direction, turns, data):
    cal = joint(zero, direction)
    low, high = cal.tick_limits()
    true = data.draw(st.integers(low, high))  # where the joint is, on its calibrated turn
    reading = true + turns * 4096  # what a servo that restarted its count may say
    assert reading + 4096 * turn_correction(reading, cal) == true


def test_a_range_of_a_turn_or_more_is_refused() -> None:
    with pytest.raises(CalibrationError, match="spans a turn or more"):
        JointCalibration(1, 2048, 1, -3.2, 3.2)

"""[hardware] operating_mode and goal_current_a: the config's checks, their application at
the loop's start (on the emulated servos' registers) and their place in /api/status."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from app.config import XM430_CURRENT_LIMIT_A, HardwareSettings, load_settings
from app.control.servo_current import check
from app.control.wrist import WristBus
from hardware.dynamixel.control_table import Reg
from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.servo_emulator import IDS
from tests.support.wait import ok_json


def test_the_defaults_are_position_mode_at_the_full_current_limit() -> None:
    hardware = load_settings().hardware
    assert hardware.operating_mode == "position"
    assert abs(XM430_CURRENT_LIMIT_A - 3.20917) < 1e-9  # 1193 units of 2.69 mA
    assert hardware.goal_currents_a() == (XM430_CURRENT_LIMIT_A,) * 3


def test_goal_current_is_one_for_all_or_one_per_leg() -> None:
    assert HardwareSettings(goal_current_a=0.5).goal_currents_a() == (0.5, 0.5, 0.5)
    per_leg = HardwareSettings(goal_current_a=(0.5, 1.0, 3.2))
    assert per_leg.goal_currents_a() == (0.5, 1.0, 3.2)


@pytest.mark.parametrize("value", [0.0, -0.5, 3.21, (0.5, 0.5, 4.0), float("nan")])
def test_a_goal_current_out_of_range_is_refused_naming_the_field(value) -> None:
    with pytest.raises(ValidationError, match="goal_current_a"):
        HardwareSettings(goal_current_a=value)


def test_an_unknown_operating_mode_is_refused_naming_the_field() -> None:
    with pytest.raises(ValidationError, match="operating_mode"):
        HardwareSettings(operating_mode="current")  # type: ignore[arg-type]


def test_the_commands_check_names_the_field_and_the_joint() -> None:
    assert check("current_based_position", [0.5, 1, 2]) == (0.5, 1.0, 2.0)
    with pytest.raises(ValueError, match="operating_mode 'pwm'"):
        check("pwm", [0.5] * 3)
    with pytest.raises(ValueError, match="goal_current_a of joint 2: 0.0 A"):
        check("position", [0.5, 0.0, 0.5])
    with pytest.raises(ValueError, match="goal_current_a: 2 values"):
        check("position", [0.5, 0.5])


def test_the_config_reaches_the_servos_at_start_and_shows_in_the_status(tmp_path) -> None:
    hardware = {"operating_mode": "current_based_position", "goal_current_a": [1.0, 0.5, 0.25]}
    with make_client(tmp_path, hardware=hardware) as client:
        take_lease(client)
        status = ok_json(client.get("/api/status"))
        assert status["servo_mode"] == "current_based_position"
        assert status["goal_current_a"] == pytest.approx([1.0, 0.5, 0.25])
        assert status["torque"] is False  # the mode is written with torque off
        emulator = client.app.state.backend.emulator
        tables = [emulator.servo(i).table for i in IDS]
        assert [t.get(Reg.OPERATING_MODE) for t in tables] == [5, 5, 5]
        # 1.0 / 2.69 mA = 371.75 -> 372; 0.5 -> 185.87 -> 186; 0.25 -> 92.94 -> 93
        assert [t.get(Reg.GOAL_CURRENT) for t in tables] == [372, 186, 93]


def test_the_default_status_says_position_mode_at_the_limit(tmp_path) -> None:
    with make_client(tmp_path) as client:
        status = ok_json(client.get("/api/status"))
        assert status["servo_mode"] == "position"
        assert status["goal_current_a"] == pytest.approx([XM430_CURRENT_LIMIT_A] * 3)
        emulator = client.app.state.backend.emulator
        assert [emulator.servo(i).table.get(Reg.OPERATING_MODE) for i in IDS] == [3, 3, 3]


class _Recorder:
    """A four-servo bus that only records Goal Current writes."""

    def __init__(self, held: list[float] | None) -> None:
        self.written: list[list[float]] = []
        if held is not None:
            self.read_goal_current = lambda: list(held)

    def set_goal_current(self, currents_a) -> None:
        self.written.append(list(currents_a))


@pytest.mark.parametrize(("held", "wrist_a"), [([3.0, 3.0, 3.0, 0.7], 0.7), (None, None)])
def test_the_wrist_keeps_its_own_goal_current(held, wrist_a) -> None:
    inner = _Recorder(held)
    wrist = WristBus(inner, servo_id=4)  # type: ignore[arg-type]
    wrist.set_goal_current([0.5, 0.6, 0.8])
    wrist.set_goal_current([1.0, 1.0, 1.0])
    expected = XM430_CURRENT_LIMIT_A if wrist_a is None else wrist_a
    assert inner.written == [[0.5, 0.6, 0.8, expected], [1.0, 1.0, 1.0, expected]]
    with pytest.raises(ValueError, match="4 leg goal currents for 3 legs"):
        wrist.set_goal_current([1.0] * 4)

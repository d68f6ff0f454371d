"""Each backend opens a four-servo bus when [wrist] is enabled, and three without it."""

from __future__ import annotations

import pytest

from app.config import load_settings
from app.server.backends import open_backend
from hardware.dynamixel.control_table import RAD_PER_TICK
from hardware.seam import SeamError
from tests.support.wait import wait_for

# its zero 548 ticks off the encoder's middle: +-1 rad (652 ticks) stays off the seam
WRIST = {
    "enabled": True,
    "servo_id": 7,
    "zero_offset_ticks": 1500,
    "direction": -1,
    "min_angle_rad": -1.0,
    "max_angle_rad": 1.0,
}


def test_the_emulated_bus_has_the_wrist_fourth_with_its_calibration() -> None:
    settings = load_settings(hardware={"backend": "emulated"}, wrist=WRIST)
    with open_backend(settings, emulator_in_process=True) as backend:
        bus, emulator = backend.bus, backend.emulator
        assert emulator is not None and [s.servo_id for s in emulator.servos] == [1, 2, 3, 7]
        emulator.place({7: 1500 - 100})  # 100 ticks below its zero, direction -1
        wait_for(
            lambda: abs(bus.read_state().position_rad[3] - 100 * RAD_PER_TICK) < 1e-9,
            "the wrist read through its calibration",
            seen=lambda: bus.read_state().position_rad,
        )
        assert bus.read_state().position_rad.shape == (4,)


def test_a_wrist_range_across_the_encoder_s_seam_is_refused_at_connect() -> None:
    wide = {**WRIST, "min_angle_rad": -3.0, "max_angle_rad": 3.0}  # -456 .. 3456 ticks
    settings = load_settings(hardware={"backend": "emulated"}, wrist=wide)
    with (
        pytest.raises(SeamError, match=r"servo 7 \(joint 4\).*crosses the encoder's seam"),
        open_backend(settings, emulator_in_process=True),
    ):
        pass


def test_without_a_wrist_every_bus_has_three_servos() -> None:
    settings = load_settings(hardware={"backend": "emulated"})
    with open_backend(settings, emulator_in_process=True) as backend:
        assert backend.bus.read_state().position_rad.shape == (3,)


@pytest.mark.slow
def test_the_simulated_bus_has_the_twin_s_wrist() -> None:
    settings = load_settings(hardware={"backend": "sim"}, wrist=WRIST)
    with open_backend(settings) as backend:
        state = backend.bus.read_state()
        assert state.position_rad.shape == (4,)
        assert state.position_rad[3] == pytest.approx(0.0, abs=RAD_PER_TICK)  # assembled at 0

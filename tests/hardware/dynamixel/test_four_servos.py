"""Three legs and a wrist on one bus: one sync write and one sync read carry all four
servos (dynamixel-sdk against the emulator; the packets checked byte for byte by hand)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from hardware.calibration import JointCalibration
from hardware.dynamixel.control_table import RAD_PER_TICK, Reg
from hardware.dynamixel.driver import DynamixelBus
from hardware.emulator import ServoEmulator
from hardware.emulator.serve import shaft_motion
from tests.support.servo_emulator import fast, make_config
from tests.support.wait import wait_for

IDS = (1, 2, 3, 4)
LEGS = tuple(JointCalibration(i, min_angle_rad=-0.6, max_angle_rad=1.65) for i in (1, 2, 3))
WRIST = JointCalibration(4, 2048, -1, -3.0, 3.0)  # mounted the other way round


def crc16(data: bytes) -> int:
    """The e-Manual's CRC-16 (polynomial 0x8005, initial 0), bit by bit: independent of
    the table-driven one in hardware/dynamixel/protocol.py and of the SDK's."""
    crc = 0
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
            crc &= 0xFFFF
    return crc


def framed(body: str) -> bytes:
    """Header + `body` (hex) + its CRC, low byte first."""
    packet = bytes.fromhex("FF FF FD 00" + body)
    return packet + crc16(packet).to_bytes(2, "little")


@pytest.fixture
def emulator() -> Iterator[ServoEmulator]:
    emu = fast(ServoEmulator(IDS))
    emu.start()
    try:
        yield emu
    finally:
        emu.stop()


@pytest.fixture
def bus(emulator: ServoEmulator) -> Iterator[DynamixelBus]:
    dxl = DynamixelBus(make_config(emulator.port, joints=(*LEGS, WRIST)))
    dxl.connect()
    try:
        yield dxl
    finally:
        dxl.disconnect()


@pytest.fixture
def sent(bus: DynamixelBus) -> list[bytes]:
    """Every packet the SDK writes on the port from now on."""
    packets: list[bytes] = []
    port = bus.link.port
    assert port is not None
    write = port.writePort

    def recording(packet: list[int]) -> int:
        packets.append(bytes(packet))
        return write(packet)

    port.writePort = recording  # type: ignore[method-assign]
    return packets


def test_one_sync_write_carries_the_four_goals(
    bus: DynamixelBus, emulator: ServoEmulator, sent: list[bytes]
) -> None:
    bus.write_goal([0.1, 0.2, 0.3, 1.0])
    # by hand, ticks = zero + direction * round(angle / (2 pi / 4096)):
    # 0.1 -> 2048 + 65 = 2113 (0x0841); 0.2 -> 2048 + 130 = 2178 (0x0882);
    # 0.3 -> 2048 + 196 = 2244 (0x08C4); wrist 1.0, reversed -> 2048 - 652 = 1396 (0x0574)
    expected = framed(
        "FE 1B 00 83"  # broadcast id, length 27 = 3 + 4 + 4 * (1 + 4), Sync Write
        "74 00 04 00"  # Goal Position (116), 4 bytes each
        "01 41 08 00 00  02 82 08 00 00  03 C4 08 00 00  04 74 05 00 00"
    )
    assert sent == [expected]
    goals = {2113: 1, 2178: 2, 2244: 3, 1396: 4}
    wait_for(
        lambda: all(emulator.servo(i).table.get(Reg.GOAL_POSITION) == t for t, i in goals.items()),
        "the four goals in the emulated servos' tables",
        seen=lambda: [emulator.servo(i).table.get(Reg.GOAL_POSITION) for i in IDS],
    )


def test_one_sync_read_returns_the_four_servos(
    bus: DynamixelBus, emulator: ServoEmulator, sent: list[bytes]
) -> None:
    emulator.place({1: 2113, 2: 2178, 3: 2244, 4: 1396})
    state = bus.read_state()
    expected = framed(
        "FE 0B 00 82"  # broadcast id, length 11 = 3 + 4 + 4 ids, Sync Read
        "7A 00 19 00"  # Moving (122) .. Present Temperature (146): 25 bytes
        "01 02 03 04"
    )
    assert sent == [expected]
    assert state.position_rad.shape == (4,) and len(state.hardware_errors) == 4
    assert state.position_rad == pytest.approx(
        [65 * RAD_PER_TICK, 130 * RAD_PER_TICK, 196 * RAD_PER_TICK, 652 * RAD_PER_TICK]
    )
    assert list(state.voltage_v) == [12.0] * 4 and not state.faulted


def test_the_wrist_follows_its_goal_through_the_driver(bus: DynamixelBus) -> None:
    legs = list(bus.read_state().position_rad[:3])
    bus.write_goal([*legs, 0.0])
    bus.torque(True)
    bus.write_goal([*legs, -0.7])
    wait_for(
        lambda: abs(bus.read_state().position_rad[3] + 0.7) <= 3 * RAD_PER_TICK,
        "the wrist at -0.7 rad",
        seen=lambda: bus.read_state().position_rad,
    )


def test_the_emulator_s_twin_emulates_the_wrist_as_the_fourth_servo() -> None:
    model = shaft_motion("twin", IDS)  # `python -m hardware.emulator --model twin --ids 1,2,3,4`
    assert model is not None
    with fast(ServoEmulator(IDS, model=model)) as emulator:
        # the emulator's twin calibrates every servo at 2048 ticks, direction +1
        wrist = JointCalibration(4, 2048, 1, -3.0, 3.0)
        dxl = DynamixelBus(make_config(emulator.port, joints=(*LEGS, wrist)))
        dxl.connect()
        try:
            legs = list(dxl.read_state().position_rad[:3])
            dxl.write_goal([*legs, 0.0])
            dxl.torque(True)
            dxl.write_goal([*legs, 0.9])
            wait_for(
                lambda: abs(dxl.read_state().position_rad[3] - 0.9) <= 3 * RAD_PER_TICK,
                "the twin's wrist at 0.9 rad through the emulator",
                seen=lambda: dxl.read_state().position_rad,
            )
        finally:
            dxl.disconnect()

"""The emulator on the wire: e-manual instruction packets in, e-manual status packets out.

No SDK here: bytes go straight through the pty, so these pin the emulator's framing to the
documented packets rather than to whatever the SDK tolerates.
"""

from __future__ import annotations

from hardware.dynamixel.control_table import Reg
from hardware.dynamixel.protocol import Instruction, PacketReader, StatusError, instruction_packet
from hardware.emulator import ServoEmulator
from tests.support.emanual import EMANUAL
from tests.support.servo_emulator import RawPort


def packet(name: str) -> bytes:
    return bytes.fromhex(EMANUAL[name])


def test_ping_answers_the_emanual_status(emulator: ServoEmulator, raw: RawPort) -> None:
    emulator.servo(1).table.set(Reg.FIRMWARE_VERSION, 0x26)
    expected = packet("ping status (XM430-W210 1030, fw 38)")
    assert raw.exchange(packet("ping"), len(expected)) == expected


def test_read_answers_the_emanual_status(emulator: ServoEmulator, raw: RawPort) -> None:
    emulator.place({1: 166})
    expected = packet("read status (166)")
    assert raw.exchange(packet("read present position"), len(expected)) == expected


def test_write_answers_and_stores(emulator: ServoEmulator, raw: RawPort) -> None:
    expected = packet("write status")
    assert raw.exchange(packet("write goal position 512"), len(expected)) == expected
    assert emulator.servo(1).table.get(Reg.GOAL_POSITION) == 512


def test_sync_read_answers_each_servo_in_order(emulator: ServoEmulator, raw: RawPort) -> None:
    emulator.place({1: 166, 2: 2079})
    first, second = packet("read status (166)"), packet("sync read status id 2 (2079)")
    reply = raw.exchange(packet("sync read ids 1, 2"), len(first) + len(second))
    assert reply == first + second


def test_sync_write_is_silent_and_applies(emulator: ServoEmulator, raw: RawPort) -> None:
    assert raw.exchange(packet("sync write 150, 170"), 1, timeout_s=0.1) == b""
    assert len(raw.exchange(packet("ping"), 14)) == 14  # answered after the write was applied
    assert emulator.servo(1).table.get(Reg.GOAL_POSITION) == 150
    assert emulator.servo(2).table.get(Reg.GOAL_POSITION) == 170


def test_reboot_and_factory_reset_answer_then_act(emulator: ServoEmulator, raw: RawPort) -> None:
    done = packet("write status")  # the e-manual's bare OK status for ID 1
    emulator.servo(1).table.set(Reg.LED, 1)
    assert raw.exchange(packet("reboot"), len(done)) == done
    assert emulator.servo(1).table.get(Reg.LED) == 0 and emulator.servo(1).reboots == 1
    emulator.servo(1).table.set(Reg.RETURN_DELAY_TIME, 3)
    assert raw.exchange(packet("factory reset 0x01"), len(done)) == done
    assert emulator.servo(1).table.get(Reg.RETURN_DELAY_TIME) == 250  # default again


def test_bad_crc_gets_a_crc_error_status(raw: RawPort) -> None:
    bad = bytearray(packet("ping"))
    bad[-2] ^= 0xFF
    (status,) = PacketReader().feed(raw.exchange(bytes(bad), 11))
    assert status.params[0] == StatusError.CRC


def test_unknown_instruction_gets_an_instruction_error(raw: RawPort) -> None:
    (status,) = PacketReader().feed(raw.exchange(instruction_packet(1, 0x7F), 11))
    assert (status.packet_id, status.params[0]) == (1, StatusError.INSTRUCTION)


def test_stuffed_status_when_data_contains_a_header(emulator: ServoEmulator, raw: RawPort) -> None:
    # A shaft at tick 0x00FDFFFF (multi-turn) reads as the bytes FF FF FD 00.
    emulator.place({1: 0x00FDFFFF})
    request = instruction_packet(1, Instruction.READ, bytes([132, 0, 4, 0]))
    reply = raw.exchange(request, 16)
    assert len(reply) == 16 and reply[9:14] == b"\xff\xff\xfd\xfd\x00"  # stuffed
    (status,) = PacketReader().feed(reply)
    assert status.crc_ok and status.params[1:] == b"\xff\xff\xfd\x00"


def test_fast_sync_read_is_one_chained_packet(emulator: ServoEmulator, raw: RawPort) -> None:
    emulator.place({1: 166, 2: 2079})
    request = instruction_packet(0xFE, Instruction.FAST_SYNC_READ, bytes([132, 0, 4, 0, 1, 2]))
    reply = raw.exchange(request, 7 + 1 + 2 * 8)
    assert reply[:8] == bytes.fromhex("FF FF FD 00 FE 11 00 55")
    assert reply[8:14] == bytes([0, 1]) + (166).to_bytes(4, "little")
    assert reply[16:22] == bytes([0, 2]) + (2079).to_bytes(4, "little")
    (status,) = PacketReader().feed(reply)
    assert status.crc_ok

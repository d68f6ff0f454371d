"""No instruction packet, however malformed, breaks the emulator or its control tables."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hardware.dynamixel.control_table import CONTROL_TABLE_SIZE, Reg
from hardware.dynamixel.protocol import Instruction, Packet
from hardware.emulator import ServoEmulator

instructions = st.sampled_from([int(i) for i in Instruction] + [0x00, 0x07, 0x7F, 0xFF])
packet_ids = st.sampled_from([1, 2, 3, 9, 0xFE])


@pytest.mark.slow
@settings(max_examples=300)
@given(st.lists(st.tuples(packet_ids, instructions, st.binary(max_size=48)), max_size=6))
def test_random_packets_never_raise(packets: list[tuple[int, int, bytes]]) -> None:
    emulator = ServoEmulator((1, 2, 3))  # not started: packets go straight to handle()
    try:
        for packet_id, instruction, params in packets:
            emulator.handle(Packet(packet_id, instruction, params, crc_ok=True))
        for servo in emulator.servos:
            assert len(servo.table.memory) == CONTROL_TABLE_SIZE
            assert servo.table.get(Reg.MODEL_NUMBER) == 1030  # read-only stays read-only
    finally:
        emulator.stop()


def test_a_client_that_never_reads_cannot_block_the_emulator() -> None:
    emulator = ServoEmulator((1,))
    try:
        read = Packet(1, Instruction.READ, bytes([0, 0, CONTROL_TABLE_SIZE, 0]), crc_ok=True)
        for _ in range(200):  # ~160 bytes each: far beyond the pty's buffer
            emulator.handle(read)
        assert emulator.unread_replies > 0
    finally:
        emulator.stop()

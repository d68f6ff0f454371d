"""Protocol 2.0 framing against the e-manual's own packets and the SDK's implementation.

The hex strings (tests/support/emanual.py) are the packet examples of the ROBOTIS e-manual
(Protocol 2.0 page: Ping, Read, Write, Sync Read, Sync Write, Reboot, Factory Reset).
"""

from __future__ import annotations

import dynamixel_sdk as sdk
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardware.dynamixel.protocol import (
    Instruction,
    PacketReader,
    crc16,
    frame,
    instruction_packet,
    status_packet,
    stuff,
    unstuff,
)
from tests.support.emanual import EMANUAL


@pytest.mark.parametrize("name", EMANUAL)
def test_crc_of_emanual_packets(name: str) -> None:
    packet = bytes.fromhex(EMANUAL[name])
    assert crc16(packet[:-2]) == int.from_bytes(packet[-2:], "little")


@pytest.mark.parametrize("name", EMANUAL)
def test_frame_rebuilds_emanual_packets_byte_for_byte(name: str) -> None:
    packet = bytes.fromhex(EMANUAL[name])
    assert frame(packet[4], unstuff(packet[7:-2])) == packet


def test_builders_match_the_emanual() -> None:
    assert instruction_packet(1, Instruction.PING) == bytes.fromhex(EMANUAL["ping"])
    read = instruction_packet(1, Instruction.READ, bytes([0x84, 0, 4, 0]))
    assert read == bytes.fromhex(EMANUAL["read present position"])
    status = status_packet(1, 0, (166).to_bytes(4, "little"))
    assert status == bytes.fromhex(EMANUAL["read status (166)"])


@given(st.binary(max_size=300))
def test_crc_equals_the_sdk_table(data: bytes) -> None:
    assert crc16(data) == sdk.Protocol2PacketHandler().updateCRC(0, list(data), len(data))


def test_crc_continues_across_chunks() -> None:
    data = bytes(range(40))
    assert crc16(data[20:], crc16(data[:20])) == crc16(data)


STUFFING_CASES = [
    (b"\x03\xff\xff\xfd", b"\x03\xff\xff\xfd\xfd"),
    (b"\x03\xff\xff\xfd\x00\xff\xff\xfd", b"\x03\xff\xff\xfd\xfd\x00\xff\xff\xfd\xfd"),
    (b"\x03\xff\xfd\xff\xfd", b"\x03\xff\xfd\xff\xfd"),  # no FF FF FD: nothing to stuff
    (b"\x03\xff\xff\xff\xfd", b"\x03\xff\xff\xff\xfd\xfd"),
]


@pytest.mark.parametrize(("body", "stuffed"), STUFFING_CASES)
def test_stuffing_cases(body: bytes, stuffed: bytes) -> None:
    assert stuff(body) == stuffed
    assert unstuff(stuffed) == body


@given(st.lists(st.sampled_from([0x00, 0xFD, 0xFF, 0x55]), max_size=40))
def test_stuffed_packets_equal_the_sdk_and_round_trip(tail: list[int]) -> None:
    body = bytes([Instruction.WRITE, 0x74, 0x00, *tail])
    packet = frame(0x01, body)
    sdk_packet = [0xFF, 0xFF, 0xFD, 0x00, 0x01, 0, 0, *body, 0, 0]
    sdk_packet[5:7] = list((len(body) + 2).to_bytes(2, "little"))
    handler = sdk.Protocol2PacketHandler()
    stuffed = handler.addStuffing(sdk_packet)
    length = int.from_bytes(bytes(stuffed[5:7]), "little")
    assert packet[:-2] == bytes(stuffed[: 7 + length - 2])
    stuffed_body = packet[7:-2]
    for i in range(len(stuffed_body) - 2):
        if stuffed_body[i : i + 3] == b"\xff\xff\xfd":  # a header look-alike must be stuffed
            assert stuffed_body[i + 3 : i + 4] == b"\xfd"
    (parsed,) = PacketReader().feed(packet)
    assert (parsed.packet_id, parsed.instruction, parsed.params, parsed.crc_ok) == (
        1,
        Instruction.WRITE,
        body[1:],
        True,
    )


def test_reader_skips_garbage_and_reassembles_split_packets() -> None:
    ping = bytes.fromhex(EMANUAL["ping"])
    write = bytes.fromhex(EMANUAL["write goal position 512"])
    reader = PacketReader()
    assert reader.feed(b"\x00\xff\x13" + ping[:5]) == []
    (first,) = reader.feed(ping[5:] + write[:3])
    (second,) = reader.feed(write[3:])
    assert first.instruction == Instruction.PING and first.crc_ok
    assert second.params == bytes([0x74, 0x00, 0x00, 0x02, 0x00, 0x00])


def test_reader_flags_a_bad_crc() -> None:
    ping = bytearray.fromhex(EMANUAL["ping"])
    ping[-1] ^= 0x01
    (packet,) = PacketReader().feed(bytes(ping))
    assert not packet.crc_ok

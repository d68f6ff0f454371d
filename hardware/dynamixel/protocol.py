"""Dynamixel Protocol 2.0 framing: CRC-16, byte stuffing, instruction and status packets.

Used by the emulator (hardware/emulator/) to speak the wire format the real servos speak;
the driver leaves framing to dynamixel-sdk. Packet layout (e-manual, Protocol 2.0):

    FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAM... | CRC_L CRC_H

LEN counts INST + PARAM + CRC after stuffing. Stuffing inserts an extra FD after every
FF FF FD that appears from INST onwards, so the header pattern never occurs inside a packet.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
MAX_ID = 0xFC
STATUS = 0x55
ALERT_BIT = 0x80


class Instruction(enum.IntEnum):
    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93
    FAST_BULK_READ = 0x9A


class StatusError(enum.IntEnum):
    """The error number in a status packet's error byte (bits 0-6)."""

    NONE = 0x00
    RESULT_FAIL = 0x01
    INSTRUCTION = 0x02
    CRC = 0x03
    DATA_RANGE = 0x04
    DATA_LENGTH = 0x05
    DATA_LIMIT = 0x06
    ACCESS = 0x07


def _crc_table() -> tuple[int, ...]:
    # CRC-16/BUYPASS: poly 0x8005, init 0, no reflection -- the table the e-manual prints.
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes | bytearray, crc: int = 0) -> int:
    """The Protocol 2.0 CRC-16 of `data`, continuing from `crc`."""
    for byte in data:
        crc = ((crc << 8) ^ _CRC_TABLE[((crc >> 8) ^ byte) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Insert FD after every FF FF FD in `body` (INST + PARAM, header not included)."""
    out = bytearray()
    for byte in body:
        out.append(byte)
        if byte == 0xFD and out[-3:-1] == b"\xff\xff" and len(out) >= 3:
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Remove the FD inserted after every FF FF FD (inverse of `stuff`)."""
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        if body[i] == 0xFD and out[-3:-1] == b"\xff\xff" and len(out) >= 3:
            i += 1  # skip the stuffing byte
        i += 1
    return bytes(out)


def frame(packet_id: int, body: bytes) -> bytes:
    """A complete packet: header, id, length, stuffed `body` (INST + PARAM), CRC."""
    stuffed = stuff(body)
    head = HEADER + bytes([packet_id]) + (len(stuffed) + 2).to_bytes(2, "little")
    crc = crc16(head + stuffed)
    return head + stuffed + crc.to_bytes(2, "little")


def instruction_packet(packet_id: int, instruction: int, params: bytes = b"") -> bytes:
    """An instruction packet for `packet_id` (use BROADCAST_ID for sync/bulk instructions)."""
    return frame(packet_id, bytes([instruction]) + params)


def status_packet(packet_id: int, error: int, params: bytes = b"") -> bytes:
    """A status packet: INST 0x55, the error byte, then `params`."""
    return frame(packet_id, bytes([STATUS, error]) + params)


@dataclass(frozen=True)
class Packet:
    """A received packet, unstuffed: id, instruction and parameters; `crc_ok` as checked."""

    packet_id: int
    instruction: int
    params: bytes
    crc_ok: bool


class PacketReader:
    """Incremental parser: feed bytes as they arrive, take whole packets out.

    Garbage before a header is dropped, as a servo on a shared bus does when it sees
    another device's reply or line noise.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[Packet]:
        """Append `data`; return every packet completed by it, in order."""
        self._buffer += data
        packets = []
        while (packet := self._next()) is not None:
            packets.append(packet)
        return packets

    def _next(self) -> Packet | None:
        start = self._buffer.find(HEADER[:3])
        if start < 0:
            del self._buffer[: max(0, len(self._buffer) - 2)]  # keep a partial header
            return None
        del self._buffer[:start]
        if len(self._buffer) < 7:
            return None
        if self._buffer[3] != 0x00:
            del self._buffer[:3]  # FF FF FD FD is a stuffed sequence, not a header
            return None if len(self._buffer) < 7 else self._next()
        length = int.from_bytes(self._buffer[5:7], "little")
        total = 7 + length
        if length < 3:
            del self._buffer[:3]
            return self._next()
        if len(self._buffer) < total:
            return None
        raw = bytes(self._buffer[:total])
        del self._buffer[:total]
        crc_ok = crc16(raw[:-2]) == int.from_bytes(raw[-2:], "little")
        body = unstuff(raw[7:-2])
        return Packet(raw[4], body[0], body[1:], crc_ok)

"""Group instructions of the emulated bus: sync/bulk read and write, fast sync/bulk read.

Sync and bulk reads get one status packet per listed servo, in the order listed (each
servo waits for the one before it, as on the real bus). Fast reads get one packet with a
block per servo: ERR, ID, DATA, CRC, where each block's CRC continues over all bytes before
it and the last block's CRC is the packet's. Writes never get an answer.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hardware.dynamixel.protocol import (
    BROADCAST_ID,
    HEADER,
    Instruction,
    Packet,
    StatusError,
    crc16,
)
from hardware.emulated_servo import Reply

# dynamixel-sdk's receive buffer (RXPACKET_MAX_LEN); no real reply is longer.
MAX_PACKET_BYTES = 1024

if TYPE_CHECKING:
    from hardware.emulated_servo import EmulatedServo
    from hardware.emulator import ServoEmulator


def handle_group(emulator: ServoEmulator, packet: Packet) -> None:
    """Execute a broadcast group instruction on the emulator's servos."""
    params = packet.params
    inst = packet.instruction
    if inst in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ, Instruction.SYNC_WRITE):
        if len(params) < 4:
            return
        address = int.from_bytes(params[0:2], "little")
        length = int.from_bytes(params[2:4], "little")
        if inst == Instruction.SYNC_WRITE:
            _sync_write(emulator, address, length, params[4:])
            return
        requests = [(servo_id, address, length) for servo_id in params[4:]]
    elif inst == Instruction.BULK_WRITE:
        _bulk_write(emulator, params)
        return
    else:
        requests = _bulk_requests(params)
    if inst in (Instruction.FAST_SYNC_READ, Instruction.FAST_BULK_READ):
        _fast_read(emulator, requests)
    else:
        _read_each(emulator, inst, requests)


def _bulk_requests(params: bytes) -> list[tuple[int, int, int]]:
    return [
        (
            params[i],
            int.from_bytes(params[i + 1 : i + 3], "little"),
            int.from_bytes(params[i + 3 : i + 5], "little"),
        )
        for i in range(0, len(params) - 4, 5)
    ]


def _read_each(emulator: ServoEmulator, inst: int, requests: list[tuple[int, int, int]]) -> None:
    for servo_id, address, length in requests:
        servo = emulator._listening(servo_id)
        if servo is not None and servo.answers(inst):
            error, data = servo.table.read(address, length)
            emulator._reply(servo, inst, Reply(error, data))


def _fast_read(emulator: ServoEmulator, requests: list[tuple[int, int, int]]) -> None:
    total = 1 + sum(length + 4 for _, _, length in requests)  # INST + blocks (last CRC = CRC)
    if total + 9 > MAX_PACKET_BYTES:
        return  # longer than any servo's packet buffer: the request is not answered
    packet = bytearray(HEADER + bytes([BROADCAST_ID]) + total.to_bytes(2, "little") + b"\x55")
    senders: list[EmulatedServo] = []
    for servo_id, address, length in requests:
        servo = emulator._listening(servo_id)
        if servo is None or not servo.answers(Instruction.FAST_SYNC_READ):
            continue  # a silent servo leaves the packet short: the client sees it corrupt
        error, data = servo.table.read(address, length)
        if error is not StatusError.NONE:
            data = bytes(length)
        packet += bytes([servo.error_byte(error), servo.servo_id]) + data
        packet += crc16(packet).to_bytes(2, "little")
        senders.append(servo)
    if senders:
        # The chained packet goes out as one; the first servo's faults stand for the lot.
        emulator.send(senders[0], bytes(packet))


def _sync_write(emulator: ServoEmulator, address: int, length: int, data: bytes) -> None:
    stride = 1 + length
    for i in range(0, len(data) - length, stride):
        servo = emulator._listening(data[i])
        if servo is not None:
            servo.write(address, data[i + 1 : i + stride])


def _bulk_write(emulator: ServoEmulator, params: bytes) -> None:
    i = 0
    while i + 5 <= len(params):
        servo_id = params[i]
        address = int.from_bytes(params[i + 1 : i + 3], "little")
        length = int.from_bytes(params[i + 3 : i + 5], "little")
        servo = emulator._listening(servo_id)
        if servo is not None:
            servo.write(address, params[i + 5 : i + 5 + length])
        i += 5 + length

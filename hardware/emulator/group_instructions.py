"""Group instructions of the emulated bus: sync/bulk read and write, fast sync/bulk read.

Sync and bulk reads get one status packet per listed servo, in the order listed (each
servo waits for the one before it, as on the real bus). Fast reads get one packet with a
block per servo: ERR, ID, DATA, CRC, where each block's CRC continues over all bytes before
it and the last block's CRC is the packet's. Writes never get an answer.

Each function finds a servo through `listening` (the servo with that id that hears the bus,
or None) and returns (servo, status packet) pairs in wire order; the emulated bus
(hardware/emulator/emulated_bus.py) sends them through each servo's injected faults.
"""

from __future__ import annotations

from collections.abc import Callable

from hardware.dynamixel.protocol import (
    BROADCAST_ID,
    HEADER,
    Instruction,
    Packet,
    StatusError,
    crc16,
    status_packet,
)
from hardware.emulator.emulated_servo import EmulatedServo

# dynamixel-sdk's receive buffer (RXPACKET_MAX_LEN); no real reply is longer.
MAX_PACKET_BYTES = 1024

Listening = Callable[[int], EmulatedServo | None]
Sent = list[tuple[EmulatedServo, bytes]]


def handle_group(listening: Listening, packet: Packet) -> Sent:
    """Execute a broadcast group instruction; the status packets it draws, in wire order."""
    params = packet.params
    inst = packet.instruction
    if inst in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ, Instruction.SYNC_WRITE):
        if len(params) < 4:
            return []
        address = int.from_bytes(params[0:2], "little")
        length = int.from_bytes(params[2:4], "little")
        if inst == Instruction.SYNC_WRITE:
            _sync_write(listening, address, length, params[4:])
            return []
        requests = [(servo_id, address, length) for servo_id in params[4:]]
    elif inst == Instruction.BULK_WRITE:
        _bulk_write(listening, params)
        return []
    else:
        requests = _bulk_requests(params)
    if inst in (Instruction.FAST_SYNC_READ, Instruction.FAST_BULK_READ):
        return _fast_read(listening, requests)
    return _read_each(listening, inst, requests)


def _bulk_requests(params: bytes) -> list[tuple[int, int, int]]:
    return [
        (
            params[i],
            int.from_bytes(params[i + 1 : i + 3], "little"),
            int.from_bytes(params[i + 3 : i + 5], "little"),
        )
        for i in range(0, len(params) - 4, 5)
    ]


def _read_each(listening: Listening, inst: int, requests: list[tuple[int, int, int]]) -> Sent:
    sent: Sent = []
    for servo_id, address, length in requests:
        servo = listening(servo_id)
        if servo is not None and servo.answers(inst):
            error, data = servo.table.read(address, length)
            sent.append((servo, status_packet(servo.servo_id, servo.error_byte(error), data)))
    return sent


def _fast_read(listening: Listening, requests: list[tuple[int, int, int]]) -> Sent:
    total = 1 + sum(length + 4 for _, _, length in requests)  # INST + blocks (last CRC = CRC)
    if total + 9 > MAX_PACKET_BYTES:
        return []  # longer than any servo's packet buffer: the request is not answered
    packet = bytearray(HEADER + bytes([BROADCAST_ID]) + total.to_bytes(2, "little") + b"\x55")
    senders: list[EmulatedServo] = []
    for servo_id, address, length in requests:
        servo = listening(servo_id)
        if servo is None or not servo.answers(Instruction.FAST_SYNC_READ):
            continue  # a silent servo leaves the packet short: the client sees it corrupt
        error, data = servo.table.read(address, length)
        if error is not StatusError.NONE:
            data = bytes(length)
        packet += bytes([servo.error_byte(error), servo.servo_id]) + data
        packet += crc16(packet).to_bytes(2, "little")
        senders.append(servo)
    if not senders:
        return []
    # The chained packet goes out as one; the first servo's faults stand for the lot.
    return [(senders[0], bytes(packet))]


def _sync_write(listening: Listening, address: int, length: int, data: bytes) -> None:
    stride = 1 + length
    for i in range(0, len(data) - length, stride):
        servo = listening(data[i])
        if servo is not None:
            servo.write(address, data[i + 1 : i + stride])


def _bulk_write(listening: Listening, params: bytes) -> None:
    i = 0
    while i + 5 <= len(params):
        servo_id = params[i]
        address = int.from_bytes(params[i + 1 : i + 3], "little")
        length = int.from_bytes(params[i + 3 : i + 5], "little")
        servo = listening(servo_id)
        if servo is not None:
            servo.write(address, params[i + 5 : i + 5 + length])
        i += 5 + length

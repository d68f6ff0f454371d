"""The one place that calls dynamixel-sdk: bounded retries, counters, errors that name ids.

`SdkLink` wraps a PortHandler/PacketHandler pair. Every call returns decoded values or
raises a hardware.errors exception naming the servo ids, the instruction, the reason and the
number of tries; nothing the SDK or the serial port throws escapes as anything else.
Communication failures (timeout, corrupt packet, reply from the wrong id) are retried up to
`max_tries`; a servo's refusal (range, limit, access error) is not, as a retry cannot help.

Matching a status packet to its request. The SDK builds, sends and frames packets (header,
stuffing, CRC, the status instruction 0x55), and its sending discards what is waiting in
the port (stale bytes). Its own receive functions take the first packet with the right id
as the answer, whatever its length: a status packet that came too late for an earlier
request (or came twice) was then read as the answer to the next one. Here every packet is
checked against its request by `receive`: the servo id, and the number of data bytes the
request draws (ping 3, read n, write/reboot 0); a packet that does not match is discarded
and counted (`BusStats.discarded`) and the wait goes on until the request's timeout. A
status with an error number is taken whatever its length (a refused read carries no data).
Protocol 2.0 carries no sequence number, so a late answer to the same question (same
servo, instruction and length) cannot be told from the answer; it is never a value of
another request.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from typing import TypeVar

import dynamixel_sdk as sdk

from hardware.bus import BusStats
from hardware.dynamixel.control_table import Reg, decode, hardware_error_names, to_unsigned
from hardware.dynamixel.protocol import ALERT_BIT, Instruction, StatusError
from hardware.errors import CommError, NotConnectedError, ServoStatusError

T = TypeVar("T")
PROTOCOL_VERSION = 2.0
EXTRA_BAUDRATES = (4_500_000,)  # X-series rates dynamixel-sdk's PortHandler does not list
READ_BLOCK_S = 1e-3  # longest wait in one read of the port; the packet timeout still rules
# What can escape the SDK on a bad packet or a vanished port: serial errors are OSErrors,
# malformed packets surface as IndexError/ValueError deep in its parsing.
_SDK_FAULTS = (OSError, IndexError, ValueError, TypeError)
# The SDK's packet buffer (unstuffed): FF FF FD 00 | ID | LEN_L LEN_H | INST | ERR | DATA | CRC
_ID, _LEN_L, _LEN_H, _INST, _ERROR, _DATA = 4, 5, 6, 7, 8, 9
_STATUS_OVERHEAD = 4  # LEN counts INST + ERR + CRC (2) besides the data
PING_DATA_BYTES = 3  # model number (2), firmware version (1)


def comm_reason(result: int) -> str:
    """The SDK's text for a COMM_* result code, without its bracketed prefix."""
    text = sdk.Protocol2PacketHandler().getTxRxResult(result)
    return text.split("] ", 1)[-1] or f"result {result}"


def status_reason(error: int) -> str:
    """A name for the error number in a status packet's error byte."""
    number = error & ~ALERT_BIT
    try:
        return f"{StatusError(number).name.lower().replace('_', ' ')} error"
    except ValueError:
        return f"unknown error number {number}"


def data_bytes(count: int) -> str:
    """'1 data byte', '25 data bytes'."""
    return f"{count} data byte{'' if count == 1 else 's'}"


@dataclass(frozen=True)
class Status:
    """A status packet taken as an answer: the servo, its error byte, its data bytes."""

    servo_id: int
    error: int
    data: bytes


@dataclass
class _Counters:
    transactions: int = 0
    failed_tries: int = 0
    retries: int = 0
    failures: int = 0
    discarded: int = 0


class SdkLink:
    """Port, packet handler, retry policy and counters of one bus."""

    def __init__(
        self, port_name: str, baudrate: int, max_tries: int = 3, min_reply_wait_s: float = 0.0
    ) -> None:
        """``min_reply_wait_s`` [s]: the least time a status packet is waited for, over the
        SDK's own timeout (e.g. for an emulator, which a loaded machine can deschedule for
        longer than any servo takes to answer); 0 keeps the SDK's."""
        if max_tries < 1:
            raise ValueError(f"max_tries {max_tries} must be >= 1")
        if not min_reply_wait_s >= 0.0:
            raise ValueError(f"min_reply_wait_s {min_reply_wait_s} must be >= 0")
        self.port_name = port_name
        self.baudrate = baudrate
        self.max_tries = max_tries
        self.min_reply_wait_s = min_reply_wait_s
        self.port: sdk.PortHandler | None = None
        self.packets = sdk.PacketHandler(PROTOCOL_VERSION)
        self.lock = threading.RLock()  # the loop and an API call may share the bus
        self._counters = _Counters()

    def open(self) -> None:
        """Open the serial port at the configured baud rate."""
        port = sdk.PortHandler(self.port_name)
        try:
            opened = port.openPort() and port.setBaudRate(self.baudrate)
            if not opened and self.baudrate in EXTRA_BAUDRATES:
                # The SDK's list of rates stops at 4 Mbps; pyserial sets the X series' 4.5 Mbps
                # as a custom rate, through the SDK's own setupPort.
                port.baudrate = self.baudrate
                opened = port.setupPort(self.baudrate)
        except _SDK_FAULTS as exc:
            raise CommError([], "open", f"cannot open {self.port_name}: {exc}") from exc
        if not opened:
            with contextlib.suppress(*_SDK_FAULTS, AttributeError):
                port.closePort()  # openPort opened it at the SDK's default rate
            raise CommError([], "open", f"{self.port_name} refused baud rate {self.baudrate}")
        # The SDK opens the port non-blocking and polls it in a Python loop until a status
        # packet is whole: that loop held the GIL for the whole wait (the server's other
        # threads then delayed the control tick). A short blocking read waits in select()
        # without the GIL and still returns the moment the bytes asked for have arrived.
        port.ser.timeout = READ_BLOCK_S
        self.port = port
        self._counters = _Counters()

    def close(self) -> None:
        """Close the port (idempotent)."""
        if self.port is not None:
            # Closing a vanished device raises; there is nothing left to release then.
            with contextlib.suppress(*_SDK_FAULTS):
                self.port.closePort()
            self.port = None

    @property
    def stats(self) -> BusStats:
        c = self._counters
        return BusStats(c.transactions, c.failed_tries, c.retries, c.failures, c.discarded)

    def require_port(self, instruction: str) -> sdk.PortHandler:
        if self.port is None:
            raise NotConnectedError([], instruction, "bus not connected")
        return self.port

    def transact(
        self,
        ids: Sequence[int],
        instruction: str,
        attempt: Callable[[], tuple[T, int, int, str]],
        max_tries: int | None = None,
    ) -> T:
        """Run `attempt` (-> value, COMM result, status error byte, note on discarded
        packets) with bounded retries (`max_tries`, default the link's)."""
        max_tries = self.max_tries if max_tries is None else max_tries
        with self.lock:
            self.require_port(instruction)
            self._counters.transactions += 1
            reason = ""
            for tries in range(1, max_tries + 1):
                try:
                    value, result, error, note = attempt()
                except _SDK_FAULTS as exc:
                    value, result, error, reason = None, sdk.COMM_RX_CORRUPT, 0, repr(exc)
                    self.release_port()
                else:
                    reason = comm_reason(result) + (f"; {note}" if note else "")
                if result == sdk.COMM_SUCCESS:
                    if error & ~ALERT_BIT:
                        self._counters.failures += 1
                        raise ServoStatusError(
                            ids, instruction, status_reason(error), error & ~ALERT_BIT, tries
                        )
                    return value  # type: ignore[return-value]
                self._counters.failed_tries += 1
                if tries < max_tries:
                    self._counters.retries += 1
            self._counters.failures += 1
            raise CommError(ids, instruction, reason, max_tries)

    def release_port(self) -> None:
        """Clear the SDK's busy flag, which an exception mid-packet leaves set for good."""
        if self.port is not None:
            self.port.is_using = False

    def count_failure(self) -> None:
        """Record a give-up decided by the caller (e.g. a group read with a bad member)."""
        self._counters.failures += 1

    def count_try(self, failed: bool, last: bool) -> None:
        """Record one try of a caller-driven retry loop."""
        if failed:
            self._counters.failed_tries += 1
            if not last:
                self._counters.retries += 1

    def count_transaction(self) -> None:
        self._counters.transactions += 1

    def wait_at_least(self, port: sdk.PortHandler) -> None:
        """Raise the port's packet timeout, just set, to ``min_reply_wait_s`` if it is less."""
        floor_ms = self.min_reply_wait_s * 1000.0
        if floor_ms > port.packet_timeout:
            port.setPacketTimeoutMillis(floor_ms)

    # -- status packets matched to their request -----------------------------------------
    def receive(
        self, port: sdk.PortHandler, ids: Collection[int], size: int
    ) -> tuple[Status | None, int, str]:
        """The next status packet from one of `ids` carrying `size` data bytes.

        Waits until the port's packet timeout (set by the caller or the SDK's send). A
        packet from another servo, or with another number of data bytes, answers some
        other request (a late, duplicated or foreign reply): it is discarded, counted, and
        the wait goes on. A status with an error number is taken whatever its length.
        Returns (status or None, COMM result, a note on what was discarded, '' if nothing).
        Raises what the SDK or the port raises (the caller's retry loop handles it).
        """
        note = ""
        while True:
            rx, result = self.packets.rxPacket(port, False)
            if result != sdk.COMM_SUCCESS:
                return None, result, note
            length = sdk.DXL_MAKEWORD(rx[_LEN_L], rx[_LEN_H]) - _STATUS_OVERHEAD
            status = Status(rx[_ID], rx[_ERROR], bytes(rx[_DATA : _DATA + max(0, length)]))
            answers = length == size or bool(status.error & ~ALERT_BIT)
            if status.servo_id in ids and answers:
                return status, result, note
            self._counters.discarded += 1
            note = (
                f"discarded a status packet from servo {status.servo_id} with "
                f"{data_bytes(length)} (expected {data_bytes(size)})"
            )

    def exchange(
        self, servo_id: int, instruction: int, params: Sequence[int], size: int
    ) -> tuple[Status | None, int, str]:
        """One try: send `instruction` with `params` to `servo_id`, take its answer.

        `size` is the number of data bytes the answer carries. Sending discards what is
        waiting in the port first (the SDK's txPacket clears the input buffer); the wait
        is the SDK's packet timeout for an answer of that size. Returns as `receive`.
        """
        port = self.require_port(Instruction(instruction).name.lower())
        packet = [0] * (10 + len(params))
        packet[_ID] = servo_id
        length = len(params) + 3  # INST + PARAM + CRC
        packet[_LEN_L], packet[_LEN_H] = sdk.DXL_LOBYTE(length), sdk.DXL_HIBYTE(length)
        packet[_INST] = instruction
        packet[8 : 8 + len(params)] = params
        result = self.packets.txPacket(port, packet)
        if result != sdk.COMM_SUCCESS:
            return None, result, ""
        port.setPacketTimeout(size + 11)  # the SDK's timeout for a status of that size
        self.wait_at_least(port)
        return self.receive(port, (servo_id,), size)

    # -- single-servo helpers ------------------------------------------------------------
    def ask(
        self,
        servo_id: int,
        name: str,
        instruction: int,
        params: Sequence[int] = (),
        size: int = 0,
        max_tries: int | None = None,
    ) -> Status:
        """Send `instruction` to `servo_id` and return its matching status (see `receive`).

        Retries as `transact`; raises CommError (no matching status), ServoStatusError
        (the servo refused), NotConnectedError.
        """

        def attempt() -> tuple[Status | None, int, int, str]:
            status, result, note = self.exchange(servo_id, instruction, params, size)
            return status, result, status.error if status is not None else 0, note

        status = self.transact([servo_id], name, attempt, max_tries)
        assert status is not None  # transact returns only on COMM_SUCCESS
        return status

    def ping(self, servo_id: int) -> int:
        """Model number of `servo_id` (CommError if it does not answer)."""
        status = self.ask(servo_id, "ping", Instruction.PING, size=PING_DATA_BYTES)
        return int.from_bytes(status.data[0:2], "little")

    def read(self, servo_id: int, reg: Reg) -> int:
        """The value of `reg` on `servo_id`, signed if the item is."""
        params = [*reg.address.to_bytes(2, "little"), *reg.size.to_bytes(2, "little")]
        status = self.ask(servo_id, f"read {reg.name}", Instruction.READ, params, reg.size)
        return decode(reg, status.data)

    def write(self, servo_id: int, reg: Reg, value: int) -> int:
        """Write `reg` on `servo_id` and wait for its status; returns the error byte."""
        data = to_unsigned(int(value), reg.size).to_bytes(reg.size, "little")
        params = [*reg.address.to_bytes(2, "little"), *data]
        return self.ask(servo_id, f"write {reg.name}", Instruction.WRITE, params).error

    def reboot(self, servo_id: int, max_tries: int | None = None) -> None:
        """Send Reboot to `servo_id` and take its status (sent before the servo restarts)."""
        self.ask(servo_id, "reboot", Instruction.REBOOT, max_tries=max_tries)

    def hardware_errors(self, servo_id: int) -> tuple[str, ...]:
        """Names of the Hardware Error Status (70) bits latched on `servo_id`."""
        return hardware_error_names(self.read(servo_id, Reg.HARDWARE_ERROR_STATUS))

    def torque_and_errors(self, servo_id: int) -> tuple[bool, tuple[str, ...]]:
        """(Torque Enable (64) on, names of the Hardware Error Status (70) bits) of
        `servo_id`, in one read of 64 .. 70: what an alerting servo's shutdown left.

        Raises CommError, ServoStatusError, NotConnectedError.
        """
        start, end = Reg.TORQUE_ENABLE, Reg.HARDWARE_ERROR_STATUS
        size = end.address + end.size - start.address
        params = [*start.address.to_bytes(2, "little"), *size.to_bytes(2, "little")]
        name = f"read {start.name}..{end.name}"
        status = self.ask(servo_id, name, Instruction.READ, params, size)
        torque = decode(start, status.data)
        errors = decode(end, status.data, end.address - start.address)
        return torque == 1, hardware_error_names(errors)

"""The one place that calls dynamixel-sdk: bounded retries, counters, errors that name ids.

`SdkLink` wraps a PortHandler/PacketHandler pair. Every call returns decoded values or
raises a hardware.errors exception naming the servo ids, the instruction, the reason and the
number of tries; nothing the SDK or the serial port throws escapes as anything else.
Communication failures (timeout, corrupt packet, reply from the wrong id) are retried up to
`max_tries`; a servo's refusal (range, limit, access error) is not, as a retry cannot help.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TypeVar

import dynamixel_sdk as sdk

from hardware.bus import BusStats
from hardware.dynamixel.control_table import Reg, decode, hardware_error_names, to_unsigned
from hardware.dynamixel.protocol import ALERT_BIT, StatusError
from hardware.errors import CommError, NotConnectedError, ServoStatusError

T = TypeVar("T")
PROTOCOL_VERSION = 2.0
EXTRA_BAUDRATES = (4_500_000,)  # X-series rates dynamixel-sdk's PortHandler does not list
READ_BLOCK_S = 1e-3  # longest wait in one read of the port; the packet timeout still rules
# What can escape the SDK on a bad packet or a vanished port: serial errors are OSErrors,
# malformed packets surface as IndexError/ValueError deep in its parsing.
_SDK_FAULTS = (OSError, IndexError, ValueError, TypeError)


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


@dataclass
class _Counters:
    transactions: int = 0
    failed_tries: int = 0
    retries: int = 0
    failures: int = 0


class SdkLink:
    """Port, packet handler, retry policy and counters of one bus."""

    def __init__(self, port_name: str, baudrate: int, max_tries: int = 3) -> None:
        if max_tries < 1:
            raise ValueError(f"max_tries {max_tries} must be >= 1")
        self.port_name = port_name
        self.baudrate = baudrate
        self.max_tries = max_tries
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
        return BusStats(c.transactions, c.failed_tries, c.retries, c.failures)

    def require_port(self, instruction: str) -> sdk.PortHandler:
        if self.port is None:
            raise NotConnectedError([], instruction, "bus not connected")
        return self.port

    def transact(
        self, ids: Sequence[int], instruction: str, attempt: Callable[[], tuple[T, int, int]]
    ) -> T:
        """Run `attempt` (-> value, COMM result, status error byte) with bounded retries."""
        with self.lock:
            self.require_port(instruction)
            self._counters.transactions += 1
            reason = ""
            for tries in range(1, self.max_tries + 1):
                try:
                    value, result, error = attempt()
                except _SDK_FAULTS as exc:
                    value, result, error, reason = None, sdk.COMM_RX_CORRUPT, 0, repr(exc)
                    self.release_port()
                else:
                    reason = comm_reason(result)
                if result == sdk.COMM_SUCCESS:
                    if error & ~ALERT_BIT:
                        self._counters.failures += 1
                        raise ServoStatusError(
                            ids, instruction, status_reason(error), error & ~ALERT_BIT, tries
                        )
                    return value  # type: ignore[return-value]
                self._counters.failed_tries += 1
                if tries < self.max_tries:
                    self._counters.retries += 1
            self._counters.failures += 1
            raise CommError(ids, instruction, reason, self.max_tries)

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

    # -- single-servo helpers ------------------------------------------------------------
    def ping(self, servo_id: int) -> int:
        """Model number of `servo_id` (CommError if it does not answer)."""
        port = self.require_port("ping")
        return self.transact([servo_id], "ping", lambda: self.packets.ping(port, servo_id))

    def read(self, servo_id: int, reg: Reg) -> int:
        """The value of `reg` on `servo_id`, signed if the item is."""
        port = self.require_port(f"read {reg.name}")

        def attempt() -> tuple[int, int, int]:
            data, result, error = self.packets.readTxRx(port, servo_id, reg.address, reg.size)
            if result == sdk.COMM_SUCCESS and len(data) != reg.size:
                return 0, sdk.COMM_RX_CORRUPT, 0
            value = decode(reg, bytes(data)) if result == sdk.COMM_SUCCESS else 0
            return value, result, error

        return self.transact([servo_id], f"read {reg.name}", attempt)

    def write(self, servo_id: int, reg: Reg, value: int) -> int:
        """Write `reg` on `servo_id` and wait for its status; returns the error byte."""
        port = self.require_port(f"write {reg.name}")
        data = list(to_unsigned(int(value), reg.size).to_bytes(reg.size, "little"))

        def attempt() -> tuple[int, int, int]:
            result, error = self.packets.writeTxRx(port, servo_id, reg.address, reg.size, data)
            return error, result, error

        return self.transact([servo_id], f"write {reg.name}", attempt)

    def hardware_errors(self, servo_id: int) -> tuple[str, ...]:
        """Names of the Hardware Error Status (70) bits latched on `servo_id`."""
        return hardware_error_names(self.read(servo_id, Reg.HARDWARE_ERROR_STATUS))

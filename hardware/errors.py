"""Exceptions of the servo bus. Each names the servo ids, the instruction and the reason.

`BusError` is the base the app catches; `CommError` is the wire failing (timeout, corrupt or
missing status packet: retry may help), `ServoStatusError` is a servo refusing an
instruction (the status packet's error number: range, limit, access...), and
`HardwareError` is a servo latched in a hardware fault (reboot clears it).
"""

from __future__ import annotations

from collections.abc import Sequence


class BusError(Exception):
    """Base of all servo-bus errors."""

    def __init__(self, ids: Sequence[int], instruction: str, reason: str, tries: int = 1) -> None:
        self.ids = tuple(ids)
        self.instruction = instruction
        self.reason = reason
        self.tries = tries
        names = ", ".join(str(i) for i in self.ids) or "-"
        after = f" after {tries} tries" if tries > 1 else ""
        super().__init__(f"{instruction} on servo {names} failed{after}: {reason}")

    def __reduce__(self):  # pickled by its fields: errors cross the simulator's process
        return type(self), (self.ids, self.instruction, self.reason, self.tries)


class NotConnectedError(BusError):
    """The port is not open (connect() not called, or disconnect() already called)."""


class CommError(BusError):
    """No valid status packet: timeout, CRC mismatch, wrong id, or the servo is missing."""


class ServoStatusError(BusError):
    """A servo answered with an error number (data range, data limit, access, ...)."""

    def __init__(
        self, ids: Sequence[int], instruction: str, reason: str, error_number: int, tries: int = 1
    ) -> None:
        self.error_number = error_number
        super().__init__(ids, instruction, reason, tries)

    def __reduce__(self):
        return type(self), (self.ids, self.instruction, self.reason, self.error_number, self.tries)


class HardwareError(BusError):
    """A servo reports a latched hardware error (overload, overheating, ...); reboot clears it."""

    def __init__(
        self, ids: Sequence[int], instruction: str, flags: dict[int, tuple[str, ...]]
    ) -> None:
        self.flags = dict(flags)
        reason = "; ".join(f"servo {i}: {', '.join(names)}" for i, names in self.flags.items())
        super().__init__(ids, instruction, f"hardware error ({reason})")

    def __reduce__(self):
        return type(self), (self.ids, self.instruction, self.flags)


class CalibrationError(ValueError):
    """A calibration record or homing input is invalid (names the joint and the value)."""

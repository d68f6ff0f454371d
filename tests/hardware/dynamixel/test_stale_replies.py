"""A status packet answers only its own request: late, duplicated and out-of-order replies.

Every read path (the state sync read, a single read of 4 or 1 bytes, ping) and a write's
status is run while status packets of other requests are on the wire, and must return its
own true value (or raise): never a value from another request. The emulator holds a stale
reply back until the next request reaches it (`late_replies`), so it arrives just before
the true answer, after the client cleared its port: no timing is involved. The true values
are distinct from every stale one (goal 1000 against a state block's leading zeros, id 1
against a goal's low byte 0xE8, model 1030 against a goal's 1000).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest

from hardware.dynamixel.control_table import STATE_BLOCK_SIZE, STATE_BLOCK_START, Reg
from hardware.dynamixel.driver import DynamixelBus
from hardware.dynamixel.protocol import BROADCAST_ID, Instruction, instruction_packet
from hardware.emulator import ServoEmulator
from hardware.errors import CommError, ServoStatusError
from tests.support.servo_emulator import IDS, RawPort, make_config
from tests.support.wait import wait_for

PLACED = {1: 1000, 2: 2000, 3: 3000}  # present = goal position [ticks] of each servo


def _u16(value: int) -> bytes:
    return value.to_bytes(2, "little")


@dataclass(frozen=True)
class Stale:
    """A request whose status packets are held back to meet a later request."""

    request: bytes
    ids: tuple[int, ...]  # the servos that answer it
    size: int  # data bytes in each answer


STALE = {
    "state block": Stale(
        instruction_packet(
            BROADCAST_ID,
            Instruction.SYNC_READ,
            _u16(STATE_BLOCK_START) + _u16(STATE_BLOCK_SIZE) + bytes(IDS),
        ),
        IDS,
        STATE_BLOCK_SIZE,
    ),
    "goal position": Stale(
        instruction_packet(1, Instruction.READ, _u16(Reg.GOAL_POSITION.address) + _u16(4)),
        (1,),
        4,
    ),
    "ping": Stale(instruction_packet(1, Instruction.PING), (1,), 3),
    "write": Stale(
        instruction_packet(1, Instruction.WRITE, _u16(Reg.LED.address) + b"\x00"), (1,), 0
    ),
}


def _sync_read(bus: DynamixelBus) -> None:
    assert bus.read_ticks() == PLACED


def _read_4(bus: DynamixelBus) -> None:
    assert bus.read_register(1, Reg.GOAL_POSITION) == PLACED[1]


def _read_1(bus: DynamixelBus) -> None:
    assert bus.read_register(1, Reg.ID) == 1


def _ping(bus: DynamixelBus) -> None:
    assert bus.link.ping(1) == 1030


def _write(bus: DynamixelBus) -> None:
    # Refused by the servo (Goal Position above Max Position Limit 4095): a stale status
    # without an error number taken as its answer would make it look accepted.
    with pytest.raises(ServoStatusError, match="data limit"):
        bus.write_register(1, Reg.GOAL_POSITION, 5000)


# each read path, with the number of data bytes its answer carries
PATHS: dict[str, tuple[Callable[[DynamixelBus], None], int]] = {
    "sync read": (_sync_read, STATE_BLOCK_SIZE),
    "read 4 bytes": (_read_4, 4),
    "read 1 byte": (_read_1, 1),
    "ping": (_ping, 3),
    "write status": (_write, 0),
}

# A stale answer from the same servo with the same length cannot be told from the answer
# (Protocol 2.0 has no sequence number; a write's status carries no address), so the
# pairs of one length are out: the driver's docs state that limit.
PAIRS = [
    (path, stale)
    for path, (_, size) in PATHS.items()
    for stale, held in STALE.items()
    if held.size != size
]


def others(size: int) -> list[Callable[[DynamixelBus], None]]:
    """The paths whose answers have another length than `size`."""
    return [check for check, other in PATHS.values() if other != size]


@pytest.fixture
def placed(emulator: ServoEmulator) -> ServoEmulator:
    emulator.place(PLACED)
    return emulator


@pytest.fixture
def raw_writer(emulator: ServoEmulator) -> Iterator[RawPort]:
    """A second client on the pty that only sends: it asks the questions whose answers
    come back late to the bus under test."""
    port = RawPort(emulator.port)
    try:
        yield port
    finally:
        port.close()


def hold_stale_answers(emulator: ServoEmulator, raw: RawPort, stale: Stale) -> int:
    """Send `stale.request` with its answers held back until the next request; their count."""
    for servo_id in stale.ids:
        emulator.inject(servo_id, late_replies=1)
    before = emulator.packets_received
    raw.write(stale.request)
    wait_for(lambda: emulator.packets_received > before, "the emulator to take the request")
    return len(stale.ids)


@pytest.mark.parametrize(("path", "stale"), PAIRS)
def test_a_late_reply_to_another_request_is_never_the_answer(
    bus: DynamixelBus, placed: ServoEmulator, raw_writer: RawPort, path: str, stale: str
) -> None:
    before = bus.stats  # connect may have retried on a loaded machine
    held = hold_stale_answers(placed, raw_writer, STALE[stale])
    check, _ = PATHS[path]
    check(bus)
    after = bus.stats
    discarded = after.discarded - before.discarded
    # each stale packet was seen and thrown away (or, after a timed-out try on a loaded
    # machine, cleared from the port by the retry)
    assert discarded == held or (after.failed_tries > before.failed_tries and discarded < held)
    for other, _ in PATHS.values():  # and nothing is left over to confuse the next requests
        other(bus)


@pytest.mark.parametrize("path", PATHS)
def test_duplicated_replies_answer_once(bus: DynamixelBus, placed: ServoEmulator, path) -> None:
    for servo_id in IDS:
        placed.inject(servo_id, duplicate_replies=1)
    check, size = PATHS[path]
    check(bus)
    for other in others(size):  # the copies are cleared or discarded, never taken
        other(bus)


def test_sync_read_replies_out_of_order_are_each_taken_by_their_id(
    bus: DynamixelBus, placed: ServoEmulator
) -> None:
    before = bus.stats
    placed.inject(1, reorder_replies=1)  # servo 1's answer comes after servo 2's
    _sync_read(bus)
    after = bus.stats
    assert (after.failed_tries, after.discarded) == (before.failed_tries, before.discarded)


@pytest.mark.slow
@pytest.mark.parametrize("path", [p for p in PATHS if p != "sync read"])
def test_a_reply_overtaken_by_the_next_one_is_not_its_answer(
    bus: DynamixelBus, placed: ServoEmulator, path: str
) -> None:
    # Servo 1's first answer waits for the bus's next status packet: the first try times
    # out, the retry's answer goes out, then the held one; neither confuses what follows.
    placed.inject(1, reorder_replies=1)
    check, size = PATHS[path]
    check(bus)
    for other in others(size):
        other(bus)


@pytest.mark.slow
def test_sync_read_failure_says_the_real_data_byte_count(
    placed: ServoEmulator, raw_writer: RawPort
) -> None:
    bus = DynamixelBus(make_config(placed.port, max_tries=1, rx_timeout_s=0.3))
    bus.connect()
    try:
        read_id = instruction_packet(2, Instruction.READ, _u16(Reg.ID.address) + _u16(1))
        hold_stale_answers(placed, raw_writer, Stale(read_id, (2,), 1))
        placed.inject(2, drop_replies=1)  # and servo 2's own answer is lost
        with pytest.raises(CommError) as info:
            bus.read_state()
        assert info.value.ids == (2,)
        assert "discarded a status packet from servo 2 with 1 data byte (expected 25 data" in str(
            info.value
        )
    finally:
        bus.disconnect()


@pytest.mark.slow  # the emulator sleeps out each late reply
@pytest.mark.parametrize("delay_s", [0.07, 0.09])
def test_a_servo_answering_after_the_timeout_never_lends_its_answer(
    placed: ServoEmulator, delay_s: float
) -> None:
    # The replay: servo 1 answers 70-90 ms late, the read timeout is 20 ms.
    bus = DynamixelBus(make_config(placed.port, rx_timeout_s=0.02))
    bus.connect()
    try:
        placed.inject(1, delay_s=delay_s)
        for _ in range(2):
            try:
                _sync_read(bus)  # a late answer to the same sync read carries true values
            except CommError as exc:
                assert 1 in exc.ids
            for check in (_read_4, _read_1, _ping):
                try:
                    check(bus)  # the true value, or no value at all
                except CommError as exc:
                    assert exc.ids == (1,)
        placed.clear_faults()

        def all_true() -> bool:
            try:
                for check, _ in PATHS.values():
                    check(bus)
            except CommError:
                return False  # late replies still draining from the emulator
            return True

        wait_for(all_true, "every path to answer with its true value")
        assert bus.stats.discarded > 0
    finally:
        bus.disconnect()

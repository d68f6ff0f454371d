"""The emulated bus alone: hand-built request bytes in, reply packets out; no pty, no thread."""

from __future__ import annotations

from hardware.dynamixel.control_table import Reg, encode
from hardware.dynamixel.protocol import BROADCAST_ID, Instruction, instruction_packet
from hardware.emulator import EmulatedBus
from tests.support.emanual import EMANUAL

FACTORY_RETURN_DELAY_S = 250 * 2e-6  # Return Delay Time 250, 2 us per unit


def packet(name: str) -> bytes:
    return bytes.fromhex(EMANUAL[name])


def still_bus(ids: tuple[int, ...] = (1, 2)) -> EmulatedBus:
    """A bus whose clock never moves, so no shaft moves between packets."""
    return EmulatedBus(ids, clock=lambda: 0.0)


def test_ping_gets_the_emanual_status_after_the_return_delay() -> None:
    bus = still_bus()
    bus.servo(1).table.set(Reg.FIRMWARE_VERSION, 0x26)
    (reply,) = bus.feed(packet("ping"))
    assert reply.packet == packet("ping status (XM430-W210 1030, fw 38)")
    assert reply.delay_s == FACTORY_RETURN_DELAY_S
    assert bus.packets_received == 1


def test_sync_read_gets_one_status_per_servo_in_the_order_listed() -> None:
    bus = still_bus()
    bus.place({1: 166, 2: 2079})
    replies = bus.feed(packet("sync read ids 1, 2"))
    assert [r.packet for r in replies] == [
        packet("read status (166)"),
        packet("sync read status id 2 (2079)"),
    ]


def test_a_request_split_across_reads_is_answered_once_complete() -> None:
    bus = still_bus()
    request = packet("read present position")
    assert bus.feed(request[:5]) == []
    (reply,) = bus.feed(request[5:])
    assert reply.packet[4] == 1  # from servo 1


def test_broadcast_ping_answers_in_id_order_and_writes_are_silent() -> None:
    bus = still_bus((3, 1, 2))
    replies = bus.feed(instruction_packet(BROADCAST_ID, Instruction.PING))
    assert [r.packet[4] for r in replies] == [1, 2, 3]
    assert bus.feed(packet("sync write 150, 170")) == []
    assert bus.servo(1).table.get(Reg.GOAL_POSITION) == 150
    assert bus.servo(2).table.get(Reg.GOAL_POSITION) == 170


def test_injected_faults_shape_the_replies() -> None:
    bus = still_bus()
    (clean,) = bus.feed(packet("ping"))
    bus.inject(1, drop_replies=1)
    assert bus.feed(packet("ping")) == []
    bus.inject(1, corrupt_replies=1, delay_s=0.01)
    (reply,) = bus.feed(packet("ping"))
    assert reply.packet == clean.packet[:-1] + bytes([clean.packet[-1] ^ 0xFF])
    assert reply.delay_s == FACTORY_RETURN_DELAY_S + 0.01
    (again,) = bus.feed(packet("ping"))  # the corruption was for one packet
    assert again.packet == clean.packet
    bus.inject(1, unplugged=True)
    assert bus.feed(packet("ping")) == []


def write(bus: EmulatedBus, servo_id: int, reg: Reg, value: int) -> None:
    params = reg.address.to_bytes(2, "little") + encode(reg, value)
    (reply,) = bus.feed(instruction_packet(servo_id, Instruction.WRITE, params))
    assert reply.packet[8] == 0, f"write {reg.name} = {value} refused"


def present(bus: EmulatedBus, servo_id: int = 1) -> int:
    bus.feed(instruction_packet(servo_id, Instruction.PING))  # a packet steps the shafts
    return bus.servo(servo_id).table.get(Reg.PRESENT_POSITION)


def test_torque_on_in_position_mode_restarts_the_count_at_one_turn() -> None:
    bus = still_bus((1,))
    bus.place({1: 5000})  # torque off: the count ran on past the seam (shaft at 904)
    assert present(bus) == 5000
    write(bus, 1, Reg.TORQUE_ENABLE, 1)
    assert present(bus) == 904


def test_a_homing_offset_does_not_move_the_seam_in_position_mode() -> None:
    # The ROBOTIS forum's report (firmware 49): Homing Offset -512, a shaft held at 3700
    # reads -396 after torque off and on: the shaft is at 3700 + 512 = 4212, one turn
    # restarts it at 4212 - 4096 = 116, and 116 - 512 = -396.
    bus = still_bus((1,))
    write(bus, 1, Reg.HOMING_OFFSET, -512)
    write(bus, 1, Reg.TORQUE_ENABLE, 1)
    bus.place({1: 3700})
    assert present(bus) == 3700
    write(bus, 1, Reg.TORQUE_ENABLE, 0)
    write(bus, 1, Reg.TORQUE_ENABLE, 1)
    assert present(bus) == -396


def test_extended_mode_counts_on_through_torque_and_restarts_at_reboot() -> None:
    bus = still_bus((1,))
    write(bus, 1, Reg.OPERATING_MODE, 4)
    bus.place({1: 5000})
    write(bus, 1, Reg.TORQUE_ENABLE, 1)
    assert present(bus) == 5000
    write(bus, 1, Reg.TORQUE_ENABLE, 0)
    write(bus, 1, Reg.HOMING_OFFSET, 4096)  # shifts Present Position at once
    assert present(bus) == 9096
    bus.feed(instruction_packet(1, Instruction.REBOOT))
    assert present(bus) == 904 + 4096  # one turn again (904), plus the offset


def test_position_mode_ignores_a_homing_offset_beyond_1024() -> None:
    bus = still_bus((1,))
    bus.place({1: 1000})
    write(bus, 1, Reg.HOMING_OFFSET, 1024)
    assert present(bus) == 2024
    write(bus, 1, Reg.HOMING_OFFSET, 2000)
    assert present(bus) == 1000  # ignored: the shaft alone
    write(bus, 1, Reg.OPERATING_MODE, 4)
    assert present(bus) == 3000  # Extended Position Control Mode applies it


def test_a_duplicated_reply_goes_out_twice_back_to_back() -> None:
    bus = still_bus()
    bus.servo(1).table.set(Reg.FIRMWARE_VERSION, 0x26)
    bus.inject(1, duplicate_replies=1)
    replies = bus.feed(packet("ping"))
    assert [r.packet for r in replies] == [packet("ping status (XM430-W210 1030, fw 38)")] * 2
    assert len(bus.feed(packet("ping"))) == 1  # one duplicate was asked for


def test_a_late_reply_goes_out_first_in_the_answer_to_the_next_request() -> None:
    bus = still_bus()
    bus.place({1: 166, 2: 2079})
    bus.inject(1, late_replies=1)
    assert bus.feed(packet("read present position")) == []  # held back
    replies = bus.feed(packet("ping"))
    assert [r.packet[7:9] for r in replies] == [b"\x55\x00"] * 2
    assert replies[0].packet == packet("read status (166)")  # the earlier request's answer
    assert replies[1].packet[5:7] == (7).to_bytes(2, "little")  # then the ping's (3 data bytes)
    # a request that draws no answer still lets a held reply out
    bus.inject(1, late_replies=1)
    bus.feed(packet("ping"))
    (held,) = bus.feed(packet("sync write 150, 170"))
    assert held.packet[4] == 1 and held.packet[5:7] == (7).to_bytes(2, "little")


def test_a_reordered_reply_goes_out_after_the_next_status_packet() -> None:
    bus = still_bus()
    bus.place({1: 166, 2: 2079})
    bus.inject(1, reorder_replies=1)
    replies = bus.feed(packet("sync read ids 1, 2"))
    assert [r.packet for r in replies] == [
        packet("sync read status id 2 (2079)"),
        packet("read status (166)"),
    ]


def test_a_rebooted_servo_is_deaf_for_its_boot_time() -> None:
    now = [0.0]
    bus = EmulatedBus((1, 2), clock=lambda: now[0])
    bus.inject(1, boot_s=0.3)
    (status,) = bus.feed(packet("reboot"))  # the status goes out before the restart
    assert status.packet[4] == 1 and bus.servo(1).reboots == 1
    now[0] = 0.29
    assert bus.feed(packet("ping")) == []
    now[0] = 0.3
    assert len(bus.feed(packet("ping"))) == 1


def test_an_ignored_request_is_not_executed_nor_answered() -> None:
    bus = still_bus()
    bus.inject(1, ignore_requests=1)
    assert bus.feed(packet("reboot")) == []
    assert bus.servo(1).reboots == 0
    assert len(bus.feed(packet("reboot"))) == 1 and bus.servo(1).reboots == 1

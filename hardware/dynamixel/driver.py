"""ServoBus on ROBOTIS Dynamixel X-series servos (XM430-W210), through dynamixel-sdk.

Per control tick: one GroupSyncWrite of Goal Position (116) for all joints, and one
GroupSyncRead of the block Moving (122) .. Present Temperature (146): the issue's Present
Current (126) .. Present Temperature block, widened by four bytes so the Moving flag comes
in the same packet. The sync read is sent with the SDK's GroupSyncRead and its replies
taken one per servo, each matched to the request by id and length (SdkLink.receive: a
late or duplicated reply to another request is discarded), so each servo's error byte is
seen: when its alert bit (0x80) is set, Torque Enable (64) .. Hardware Error Status (70) is
read in one packet and the errors reported by name. A read in which any servo is missing,
late, corrupt or answers as another id is retried whole (up to `max_tries`) and otherwise
raises CommError naming the servos; no state is ever assembled from a partial reply.
Configuration writes go one servo at a time and wait for each status.

Each state's `torque_enabled` is each servo's Torque Enable (64) as last *read* from it,
never as last written: it is read at connect, after every torque write (torque(),
write_register) and reboot, and with the errors of every servo whose alert bit is set. A
servo turns its own torque off only by its Shutdown (63), which latches a hardware error and
so sets the alert bit: an overload that drops torque shows in the next state.

At connect each servo's Operating Mode, Homing Offset and Min/Max Position Limit are read:
a joint range the servo cannot reach in its mode (the encoder's seam, hardware/seam.py) is
refused with the fix, a multi-turn servo that came up a turn away from its calibration is
put back by its Homing Offset, and every goal is checked against the limits the servo
enforces before it is sent (a sync write has no status packet: a refused goal would
otherwise leave the joint where it was, silently).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import dynamixel_sdk as sdk
import numpy as np

from hardware.bus import (
    BusStats,
    JointState,
    PositionGains,
    ServoInfo,
    goal_current_units,
    per_joint,
)
from hardware.calibration import JointCalibration, goal_ticks
from hardware.dynamixel.control_table import (
    AMPERE_PER_CURRENT_UNIT,
    MODEL_NUMBER_XM430_W210,
    STATE_BLOCK_SIZE,
    STATE_BLOCK_START,
    OperatingMode,
    Reg,
    current_to_ampere,
    decode,
    profile_units,
    pwm_to_fraction,
    velocity_to_rad_s,
    voltage_to_volt,
)
from hardware.dynamixel.link import SdkLink, comm_reason, status_reason
from hardware.dynamixel.protocol import ALERT_BIT, StatusError
from hardware.encoder import TICKS_PER_REV
from hardware.errors import BusError, CalibrationError, CommError, HardwareError, ServoStatusError
from hardware.seam import (
    MULTI_TURN_MODES,
    POSITION_LIMIT_RANGE,
    SeamError,
    ServoSetup,
    check_joint,
    single_turn,
    turn_correction,
)

_SETUP_REGISTERS = frozenset(
    {Reg.OPERATING_MODE, Reg.HOMING_OFFSET, Reg.MIN_POSITION_LIMIT, Reg.MAX_POSITION_LIMIT}
)


@dataclass(frozen=True)
class DynamixelConfig:
    """Bus settings: port, baud rate [bit/s], joints in order, retry and timeout policy.

    rx_timeout_s: status timeout [s] of the per-tick sync read (None: the SDK's own, about
    34 ms plus wire time, sized for a 16 ms USB latency timer); the read's worst case is
    max_tries * rx_timeout_s. expected_model: refuse other servos at connect (None: any).
    connect_timeout_s: how long connect keeps pinging a servo that has not answered yet
    [s] (a servo still booting, an emulator not yet scheduled on a loaded machine).
    reboot_timeout_s: how long a rebooted servo may stay silent before reboot() gives up
    [s] (per round of Reboot instructions, at most max_tries rounds).
    min_reply_wait_s: the least time any status packet is waited for [s], over the SDK's
    timeout (0: the SDK's alone). For an emulator, which a loaded machine can deschedule
    for longer than a servo ever takes; real servos keep 0.
    """

    joints: tuple[JointCalibration, ...]
    port: str = "/dev/ttyUSB0"
    baudrate: int = 1_000_000
    max_tries: int = 3
    rx_timeout_s: float | None = None
    expected_model: int | None = MODEL_NUMBER_XM430_W210
    reboot_timeout_s: float = 2.0
    connect_timeout_s: float = 1.0
    min_reply_wait_s: float = 0.0

    def __post_init__(self) -> None:
        ids = [joint.servo_id for joint in self.joints]
        if not ids or len(set(ids)) != len(ids):
            raise ValueError(f"joint servo ids {ids} must be distinct and non-empty")


class DynamixelBus:
    """The control loop's bus: SI units in and out, one write and one read per tick."""

    carries_load = True  # real or simulated links under gravity (the loop compensates)

    def __init__(self, config: DynamixelConfig) -> None:
        self.config = config
        self.ids = tuple(joint.servo_id for joint in config.joints)
        self.link = SdkLink(config.port, config.baudrate, config.max_tries, config.min_reply_wait_s)
        self._goal_writer: sdk.GroupSyncWrite | None = None
        self._state_reader: sdk.GroupSyncRead | None = None
        self._setups: dict[int, ServoSetup] = {}  # per servo id, read at connect
        self._torque_on: dict[int, bool] = {}  # Torque Enable (64) as last read, per id

    # -- ServoBus ------------------------------------------------------------------------
    def connect(self, verify_calibration: bool = True) -> None:
        """Open the port, ping every joint's servo, check its model and read its setup.

        verify_calibration: also refuse joint ranges the servos cannot reach in their
        operating mode and put multi-turn servos on their calibrated turn
        (`check_calibration`); homing turns it off, since it replaces the calibration.
        Raises CommError / BusError (servos missing, wrong model), SeamError.
        """
        self.disconnect()  # reconnecting must not leak the previous port
        self.link.open()
        port = self.link.port
        goal = Reg.GOAL_POSITION
        self._goal_writer = sdk.GroupSyncWrite(port, self.link.packets, goal.address, goal.size)
        self._state_reader = sdk.GroupSyncRead(
            port, self.link.packets, STATE_BLOCK_START, STATE_BLOCK_SIZE
        )
        for servo_id in self.ids:
            self._goal_writer.addParam(servo_id, [0, 0, 0, 0])
            self._state_reader.addParam(servo_id)
        try:
            found = self._wait_for_servos()
            missing = [i for i in self.ids if i not in found]
            if missing:
                raise CommError(missing, "ping", "servo not found on the bus")
            wrong = [i for i in self.ids if self._wrong_model(found[i].model_number)]
            if wrong:
                models = ", ".join(str(found[i].model_number) for i in wrong)
                expected = self.config.expected_model
                raise BusError(wrong, "ping", f"model {models}, expected {expected}")
            self.read_setups(self.ids)
            self.read_torque(self.ids)
            if verify_calibration:
                self.check_calibration()
        except (BusError, CalibrationError):
            self.disconnect()
            raise

    def _wait_for_servos(self) -> dict[int, ServoInfo]:
        """Ping every joint until it answers or connect_timeout_s has passed; who answered.

        One round of pings (each with the link's retries) always runs; the servos still
        silent are asked again until the deadline, so a servo that is slow to answer at
        first (booting, or an emulator not yet scheduled) does not fail the connect.
        """
        deadline = time.monotonic() + self.config.connect_timeout_s
        found: dict[int, ServoInfo] = {}
        while True:
            for servo_id in [i for i in self.ids if i not in found]:
                try:
                    found.update((info.servo_id, info) for info in self.scan([servo_id]))
                except CommError:
                    continue  # answered the ping, then missed the firmware read: ask again
            if len(found) == len(self.ids) or time.monotonic() >= deadline:
                return found

    def disconnect(self) -> None:
        self.link.close()
        self._goal_writer = self._state_reader = None
        self._setups = {}
        self._torque_on = {}

    def scan(self, ids: Sequence[int] | None = None) -> list[ServoInfo]:
        found = []
        for servo_id in self.ids if ids is None else ids:
            try:
                model = self.link.ping(servo_id)
            except CommError:
                continue  # absent: scanning is how one finds out
            firmware = self.link.read(servo_id, Reg.FIRMWARE_VERSION)
            found.append(ServoInfo(servo_id, model, firmware))
        return found

    def torque(self, enabled: bool) -> None:
        """Torque Enable on all joints, then each servo's Torque Enable read back.

        Raises NotConnectedError, CommError, ServoStatusError; HardwareError when enabling
        a servo latched in a hardware fault (the servos after it are not written; what
        each servo holds is read back all the same).
        """
        if enabled:
            # Hold where the links are: a stale Goal Position would jump the arm on enable.
            # In Position Control Mode the count restarts at one turn as torque comes on.
            hold = self.read_ticks()
            for servo_id, setup in self._setups.items():
                if setup.mode == OperatingMode.POSITION:
                    hold[servo_id] = single_turn(hold[servo_id], setup.offset_in_force)
            self._sync_write_goal_ticks([hold[i] for i in self.ids])
        refused: HardwareError | None = None
        for servo_id in self.ids:
            error = self.link.write(servo_id, Reg.TORQUE_ENABLE, int(enabled))
            if enabled and error & ALERT_BIT:
                # The names come from this servo's Hardware Error Status, never the alert
                # bit alone: a servo whose register reads 0 has nothing latched.
                names = self.link.hardware_errors(servo_id)
                if names:
                    refused = HardwareError([servo_id], "write TORQUE_ENABLE", {servo_id: names})
                    break
        self.read_torque(self.ids)  # what the servos hold, not what was asked
        if refused is not None:
            raise refused

    def set_operating_mode(self, mode: OperatingMode) -> None:
        """Operating Mode (11) on all joints, one servo at a time (an EEPROM item).

        The servo itself refuses it while its torque is on (Access Error): the first such
        servo raises ServoStatusError and the servos after it are not written. The firmware
        resets Goal Current and Goal PWM to their limits on a mode change: set the goal
        current after the mode. Raises NotConnectedError, CommError, ServoStatusError.
        """
        self._write_all(Reg.OPERATING_MODE, [int(mode)] * len(self.ids))
        self.read_setups(self.ids)
        self._align_turns(self.ids)  # a mode change resets the count to one turn

    def set_goal_current(self, currents_a: Sequence[float]) -> None:
        """Goal Current (102) per joint [A], shape (n_joints,), one servo at a time.

        Each value is checked against the Current Limit (38) read from its servo (in
        2.69 mA units) before anything is written, so a refused value leaves every servo
        as it was; a RAM item, written with torque on or off (the firmware takes it either
        way). In Current-based Position Control Mode the firmware bounds the motor current
        by it (torque <= Kt * Goal Current).

        Raises ValueError naming the joint, the value and the limit (`goal_current_units`),
        or for a sequence of the wrong length; NotConnectedError, CommError,
        ServoStatusError.
        """
        if len(currents_a) != len(self.ids):
            raise ValueError(
                f"goal currents for {len(currents_a)} joints: the bus has {len(self.ids)}"
            )
        limits = [self.link.read(i, Reg.CURRENT_LIMIT) for i in self.ids]
        self._write_all(
            Reg.GOAL_CURRENT, goal_current_units(currents_a, limits, AMPERE_PER_CURRENT_UNIT)
        )

    def read_goal_current(self) -> list[float]:
        """Each joint's Goal Current (102) as its servo holds it [A], in joint order.

        Raises NotConnectedError, CommError, ServoStatusError.
        """
        return [current_to_ampere(self.link.read(i, Reg.GOAL_CURRENT)) for i in self.ids]

    def write_goal(self, positions_rad: Sequence[float]) -> None:
        ticks = goal_ticks(self.config.joints, positions_rad)
        self._sync_write_goal_ticks(ticks)

    def read_state(self) -> JointState:
        raw, alerts = self._read_block()
        return self._state_from(raw, alerts)

    def set_profile(self, velocity_rad_s: float, acceleration_rad_s2: float) -> None:
        """Profile Velocity [rad/s] and Acceleration [rad/s^2] on all joints (0 = unlimited).

        Each is rounded to register units (`profile_units`); a positive request below
        half a unit is written as 1 unit (0.024 rad/s, 0.375 rad/s^2), never as 0, which
        the XM430 reads as unlimited; a value so raised is logged as a warning naming the
        value written.

        Raises ValueError for a negative or non-finite value; NotConnectedError, CommError,
        ServoStatusError.
        """
        velocity, acceleration = profile_units(velocity_rad_s, acceleration_rad_s2)
        n = len(self.ids)
        self._write_all(Reg.PROFILE_ACCELERATION, [acceleration] * n)
        self._write_all(Reg.PROFILE_VELOCITY, [velocity] * n)

    def set_gains(self, gains: PositionGains | Sequence[PositionGains]) -> None:
        each = per_joint(gains, len(self.ids))
        self._write_all(Reg.POSITION_P_GAIN, [g.p for g in each])
        self._write_all(Reg.POSITION_I_GAIN, [g.i for g in each])
        self._write_all(Reg.POSITION_D_GAIN, [g.d for g in each])
        self._write_all(Reg.FEEDFORWARD_1ST_GAIN, [g.feedforward_1st for g in each])
        self._write_all(Reg.FEEDFORWARD_2ND_GAIN, [g.feedforward_2nd for g in each])

    def read_gains(self) -> list[PositionGains]:
        read = self.link.read
        return [
            PositionGains(
                p=read(i, Reg.POSITION_P_GAIN),
                i=read(i, Reg.POSITION_I_GAIN),
                d=read(i, Reg.POSITION_D_GAIN),
                feedforward_1st=read(i, Reg.FEEDFORWARD_1ST_GAIN),
                feedforward_2nd=read(i, Reg.FEEDFORWARD_2ND_GAIN),
            )
            for i in self.ids
        ]

    def reboot(self, ids: Sequence[int] | None = None) -> None:
        """Reboot servos (default all joints); returns once each answers pings again.

        Each servo gets one Reboot instruction, whose status it sends before it restarts;
        a lost status is not resent at once (a second Reboot would meet a booting servo).
        Then each is pinged until it answers, for at most `reboot_timeout_s` [s], so that
        nothing (torque on, a read) reaches a servo that is still booting. A servo whose
        status was lost and whose Hardware Error Status is still non-zero once it answers
        may not have rebooted: it is sent Reboot again, for at most `max_tries` rounds.

        Raises NotConnectedError; CommError naming the servos that did not answer within
        `reboot_timeout_s`, or that never confirmed a Reboot while their error stayed
        latched; ServoStatusError if a servo refuses the instruction.
        """
        targets = list(self.ids if ids is None else ids)
        unconfirmed = list(targets)
        self.link.require_port("reboot")
        rounds = self.link.max_tries
        for _ in range(rounds):
            lost = []
            for servo_id in unconfirmed:
                try:
                    self.link.reboot(servo_id, max_tries=1)
                except CommError:
                    lost.append(servo_id)  # it may have rebooted: the register will tell
            deadline = time.monotonic() + self.config.reboot_timeout_s
            for servo_id in unconfirmed:
                self._wait_back(servo_id, deadline)
            unconfirmed = [i for i in lost if self.link.read(i, Reg.HARDWARE_ERROR_STATUS) != 0]
            if not unconfirmed:
                self._align_turns(targets)  # a reboot resets the count to one turn
                self.read_torque(targets)  # back with torque off
                return
        reason = "no status to a Reboot instruction and Hardware Error Status still set"
        raise CommError(unconfirmed, "reboot", reason, rounds)

    def _wait_back(self, servo_id: int, deadline: float) -> None:
        """Ping `servo_id` until it answers (CommError once `deadline` has passed)."""
        while True:
            try:
                self.link.ping(servo_id)
                return
            except CommError as exc:
                if time.monotonic() >= deadline:
                    timeout = self.config.reboot_timeout_s
                    reason = f"did not answer a ping within {timeout} s of its Reboot"
                    raise CommError([servo_id], "reboot", reason) from exc

    @property
    def stats(self) -> BusStats:
        return self.link.stats

    # -- beyond the ServoBus protocol: setup and homing ---------------------------------
    def read_ticks(self) -> dict[int, int]:
        """Raw Present Position [ticks] per servo id (for homing; one sync read)."""
        raw, _ = self._read_block()
        offset = Reg.PRESENT_POSITION.address - STATE_BLOCK_START
        return {i: decode(Reg.PRESENT_POSITION, raw[i], offset) for i in self.ids}

    def read_register(self, servo_id: int, reg: Reg) -> int:
        """Any control-table item of one servo, raw (signed items decoded as signed)."""
        return self.link.read(servo_id, reg)

    def write_register(self, servo_id: int, reg: Reg, value: int) -> None:
        """Any writable item of one servo, raw; EEPROM items need torque off."""
        self.link.write(servo_id, reg, value)
        if reg in _SETUP_REGISTERS and servo_id in self.ids:
            self.read_setups([servo_id])
        if reg == Reg.TORQUE_ENABLE and servo_id in self.ids:
            self.read_torque([servo_id])

    def read_torque(self, ids: Sequence[int] | None = None) -> dict[int, bool]:
        """Read Torque Enable (64) of `ids` (default: every joint) afresh; every state's
        `torque_enabled` reports what was read last. Returns it per servo id.

        Raises NotConnectedError, CommError, ServoStatusError.
        """
        for servo_id in self.ids if ids is None else ids:
            self._torque_on[servo_id] = self.link.read(servo_id, Reg.TORQUE_ENABLE) == 1
        return dict(self._torque_on)

    def write_position_limits(self) -> None:
        """Copy each joint's calibrated angle limits into Min/Max Position Limit (EEPROM,
        torque off), so the servo itself refuses goals outside them in Position Control Mode.

        Raises SeamError (nothing written) if a joint's tick range is not inside 0 .. 4095,
        the registers' range: its range crosses the encoder's seam (hardware/seam.py).
        """
        first, last = POSITION_LIMIT_RANGE
        for joint, cal in enumerate(self.config.joints, start=1):
            low, high = cal.tick_limits()
            if low < first or high > last:
                raise SeamError(
                    f"servo {cal.servo_id} (joint {joint}): joint range {cal.min_angle_rad} .. "
                    f"{cal.max_angle_rad} rad is {low} .. {high} ticks; Min/Max Position "
                    f"Limit take {first} .. {last}: the range crosses the encoder's seam "
                    "(connect() and homing say how to fix it); no limit was written"
                )
        for cal in self.config.joints:
            low, high = cal.tick_limits()
            self.link.write(cal.servo_id, Reg.MIN_POSITION_LIMIT, low)
            self.link.write(cal.servo_id, Reg.MAX_POSITION_LIMIT, high)
        self.read_setups(self.ids)

    def check_calibration(self) -> None:
        """Refuse joint ranges the servos cannot reach in their operating mode, and put each
        multi-turn servo that came up a turn away from its calibration back on its turn.

        Raises SeamError naming the servo, the joint, the ticks and the fix; ServoStatusError
        if a Homing Offset cannot be written (torque on).
        """
        for joint, cal in enumerate(self.config.joints, start=1):
            check_joint(cal, self._setups[cal.servo_id], joint)
        self._align_turns(self.ids)

    def read_setups(self, ids: Sequence[int] | None = None) -> dict[int, ServoSetup]:
        """Read Operating Mode, Homing Offset and Min/Max Position Limit of `ids` (default:
        every joint) afresh; the goal checks use what was read last."""
        for servo_id in self.ids if ids is None else ids:
            read = self.link.read
            self._setups[servo_id] = ServoSetup(
                mode=read(servo_id, Reg.OPERATING_MODE),
                homing_offset=read(servo_id, Reg.HOMING_OFFSET),
                min_position=read(servo_id, Reg.MIN_POSITION_LIMIT),
                max_position=read(servo_id, Reg.MAX_POSITION_LIMIT),
            )
        return dict(self._setups)

    # -- internals -----------------------------------------------------------------------
    def _wrong_model(self, model: int) -> bool:
        return self.config.expected_model is not None and model != self.config.expected_model

    def _write_all(self, reg: Reg, values: Sequence[int]) -> None:
        for servo_id, value in zip(self.ids, values, strict=True):
            self.link.write(servo_id, reg, value)

    def _align_turns(self, ids: Sequence[int]) -> None:
        """Homing Offset += 4096 k on each multi-turn servo in `ids` that reads k turns away
        from the middle of its joint's range (its count restarts at one turn at power-on,
        reboot and mode change; hardware/seam.py)."""
        joints = {cal.servo_id: cal for cal in self.config.joints}
        multi = [i for i in ids if self._setups[i].mode in MULTI_TURN_MODES]
        if not multi:
            return
        present = self.read_ticks()
        for servo_id in multi:
            turns = turn_correction(present[servo_id], joints[servo_id])
            if turns:
                offset = self._setups[servo_id].homing_offset + turns * TICKS_PER_REV
                self.write_register(servo_id, Reg.HOMING_OFFSET, offset)

    def _check_goals(self, ticks: Sequence[int]) -> None:
        """Refuse goals a servo would refuse (outside its Min/Max Position Limit in Position
        Control Mode), naming each servo: a sync write gets no status to say so."""
        refused = []
        for servo_id, value in zip(self.ids, ticks, strict=True):
            setup = self._setups.get(servo_id)
            if setup is None:
                continue
            low, high = setup.goal_bounds()
            if not low <= value <= high:
                refused.append((servo_id, int(value), low, high))
        if refused:
            reason = "; ".join(
                f"servo {i}: goal {value} ticks outside its limits {low} .. {high}"
                for i, value, low, high in refused
            )
            raise ServoStatusError(
                [i for i, *_ in refused],
                "sync write GOAL_POSITION",
                f"{reason} (data limit error: the servo would ignore it; nothing was sent)",
                int(StatusError.DATA_LIMIT),
            )

    def _sync_write_goal_ticks(self, ticks: Sequence[int]) -> None:
        writer = self._goal_writer
        if writer is None:
            self.link.require_port("sync write GOAL_POSITION")
            return
        self._check_goals(ticks)
        with self.link.lock:  # the parameters and the packet they build belong together
            for servo_id, value in zip(self.ids, ticks, strict=True):
                writer.changeParam(servo_id, list(int(value).to_bytes(4, "little", signed=True)))
            self.link.transact(
                self.ids, "sync write GOAL_POSITION", lambda: (None, writer.txPacket(), 0, "")
            )

    def _read_block(self) -> tuple[dict[int, bytes], dict[int, tuple[str, ...]]]:
        """State-block bytes per servo id, and the hardware errors of servos that alert."""
        reader = self._state_reader
        instruction = "sync read MOVING..PRESENT_TEMPERATURE"
        port = self.link.require_port(instruction)
        with self.link.lock:
            self.link.count_transaction()
            failed: dict[int, str] = {}
            for tries in range(1, self.link.max_tries + 1):
                replies, failed = self._read_block_once(reader, port)
                last = tries == self.link.max_tries
                self.link.count_try(bool(failed), last)
                if not failed:
                    alerts = {}
                    for i, (_, error) in replies.items():
                        if error & ALERT_BIT:  # a shutdown may have turned its torque off
                            self._torque_on[i], alerts[i] = self.link.torque_and_errors(i)
                    return {i: data for i, (data, _) in replies.items()}, alerts
            self.link.count_failure()
            reason = "; ".join(f"servo {i}: {why}" for i, why in failed.items())
            raise CommError(sorted(failed), instruction, reason, self.link.max_tries)

    def _read_block_once(
        self, reader: sdk.GroupSyncRead, port: sdk.PortHandler
    ) -> tuple[dict[int, tuple[bytes, int]], dict[int, str]]:
        """One try of the sync read: each servo's (state block, error byte), and why the
        others failed. Replies are taken in any order, each from a servo still awaited and
        with the block's length; anything else is discarded (SdkLink.receive)."""
        try:
            result = reader.txPacket()
        except (OSError, IndexError, ValueError) as exc:
            self.link.release_port()
            return {}, {i: repr(exc) for i in self.ids}
        if result != sdk.COMM_SUCCESS:
            return {}, {i: comm_reason(result) for i in self.ids}
        replies: dict[int, tuple[bytes, int]] = {}
        failed: dict[int, str] = {}
        discarded: list[str] = []  # what this try threw away, to say why it failed
        pending = list(self.ids)
        while pending:
            if self.config.rx_timeout_s is not None:  # else the SDK's, for the whole read
                port.setPacketTimeoutMillis(self.config.rx_timeout_s * 1000.0)
            self.link.wait_at_least(port)
            try:
                status, result, note = self.link.receive(port, pending, STATE_BLOCK_SIZE)
            except (OSError, IndexError, ValueError) as exc:
                self.link.release_port()
                failed.update((i, repr(exc)) for i in pending)
                break
            discarded += [note] if note else []
            if status is None:
                reason = "; ".join([comm_reason(result), *discarded])
                failed.update((i, reason) for i in pending)
                break
            pending.remove(status.servo_id)
            if status.error & ~ALERT_BIT:
                failed[status.servo_id] = status_reason(status.error)
            else:
                replies[status.servo_id] = (status.data, status.error)
        return replies, failed

    def _state_from(self, raw: dict[int, bytes], alerts: dict[int, tuple[str, ...]]) -> JointState:
        def column(reg: Reg) -> np.ndarray:
            offset = reg.address - STATE_BLOCK_START
            return np.array([decode(reg, raw[i], offset) for i in self.ids], dtype=float)

        sign = np.array([cal.direction for cal in self.config.joints], dtype=float)
        ticks = column(Reg.PRESENT_POSITION)
        torque = [self._torque_on.get(i) for i in self.ids]
        position = [cal.to_rad(t) for cal, t in zip(self.config.joints, ticks, strict=True)]
        return JointState(
            position_rad=np.array(position),
            velocity_rad_s=sign * velocity_to_rad_s(column(Reg.PRESENT_VELOCITY)),
            current_a=sign * current_to_ampere(column(Reg.PRESENT_CURRENT)),
            voltage_v=voltage_to_volt(column(Reg.PRESENT_INPUT_VOLTAGE)),
            temperature_c=column(Reg.PRESENT_TEMPERATURE),
            pwm=sign * pwm_to_fraction(column(Reg.PRESENT_PWM)),
            moving=column(Reg.MOVING).astype(bool),
            hardware_errors=tuple(alerts.get(i, ()) for i in self.ids),
            stamp_s=time.monotonic(),
            torque_enabled=None if None in torque else tuple(bool(t) for t in torque),
        )

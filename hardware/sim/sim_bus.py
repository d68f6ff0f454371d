"""The MuJoCo twin as a ServoBus: the in-process simulated backend of `deltadash serve`.

Same units and behaviour as hardware.dynamixel.driver.DynamixelBus: goals clamped to the
calibrated limits and rounded to whole ticks; present values quantized as the control
table holds them (position in ticks, velocity in 0.229 rpm, current in 2.69 mA, voltage in
0.1 V, temperature in whole degC); latched hardware errors reported by name and refusing
torque until a reboot; EEPROM items refused while torque is on. With `realtime` a thread
steps the physics to follow the wall clock (the server's case); without, the caller moves
simulated time with `advance` (tests, headless runs, faster than real time).
"""

from __future__ import annotations

import atexit
import threading
import time
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from hardware.base_motion import BaseMotion
from hardware.bus import (
    BusStats,
    JointState,
    PositionGains,
    ServoInfo,
    goal_current_units,
    per_joint,
)
from hardware.calibration import goal_ticks
from hardware.dynamixel.control_table import (
    AMPERE_PER_CURRENT_UNIT,
    MODEL_NUMBER_XM430_W210,
    RAD_PER_TICK,
    OperatingMode,
    Reg,
    acceleration_to_rad_s2,
    ampere_to_current,
    current_to_ampere,
    hardware_error_names,
    profile_units,
    pwm_to_fraction,
    rad_s_to_velocity,
    velocity_to_rad_s,
)
from hardware.errors import BusError, HardwareError, NotConnectedError
from hardware.sim.surfaces import TwinContact
from hardware.sim.twin import DeltaTwin, TwinConfig
from kinematics.identification import MeasurementFrame

FIRMWARE_VERSION = 46
MOVING_THRESHOLD_UNITS = Reg.MOVING_THRESHOLD.value.default  # looked up once: enums are slow
# Shutdown (63) at its factory value (overheating, electrical shock, overload): the errors
# for which the XM430 turns its own Torque Enable off
SHUTDOWN_MASK = Reg.SHUTDOWN.value.default
MAX_CATCH_UP_S = 0.25  # as the emulator: after a stall, simulated time runs slow, never fast


@dataclass(frozen=True)
class SimBusConfig:
    """The simulated bus: the twin's design and servos, real-time pacing and the external
    measurement of the platform (what motion capture reports, thesis ch. 6.1).

    realtime: step physics in a thread to follow the wall clock; marker_offset_m: where the
    marker sits relative to the platform centre, in the base frame [m]; noise_std_m: white
    noise on each axis of the measurement [m]; seed: the noise generator's seed;
    torque_on_at_start: False powers up like the real servos (torque off, the arm hangs);
    True starts holding the assembled home pose (convenient for demos and tests);
    measurement_frame_position_m, measurement_frame_rpy_rad: the measurement's frame in the
    base frame (origin [m]; roll, pitch, yaw [rad], Rz Ry Rx): the measurement is
    Rm^T (P + marker - tm) + noise (kinematics.identification.MeasurementFrame).
    current_noise_a: white noise on each Present Current read, before it is rounded to
    the register's 2.69 mA [A] (0: none; a real XM430 reads a few units of noise), from
    its own generator (seed + 1) so the measurement's noise stays as it was.
    """

    twin: TwinConfig = TwinConfig()
    realtime: bool = True
    marker_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    noise_std_m: float = 0.0
    seed: int = 0
    torque_on_at_start: bool = False
    measurement_frame_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    measurement_frame_rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    current_noise_a: float = 0.0

    def __post_init__(self) -> None:
        noise = self.current_noise_a
        if not (isinstance(noise, int | float) and np.isfinite(noise) and 0.0 <= noise <= 1.0):
            raise ValueError(f"current_noise_a = {noise!r}: must be within 0 .. 1 A")

    @property
    def measurement_frame(self) -> MeasurementFrame:
        """The external measurement's frame in the base frame."""
        return MeasurementFrame(self.measurement_frame_position_m, self.measurement_frame_rpy_rad)


def external_measurement(
    config: SimBusConfig, platform_m: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """What motion capture reports of the true platform centre `platform_m` (base frame
    [m]): the marker, in the measurement frame, with the configured noise, shape (3,)."""
    marker = config.measurement_frame.from_base(platform_m + np.asarray(config.marker_offset_m))
    noise = rng.normal(0.0, config.noise_std_m, 3) if config.noise_std_m else 0.0
    return marker + noise


# Buses whose physics thread runs. A daemon thread still inside MuJoCo when the interpreter
# finalizes crashes the process (segfault or "terminate called without an active
# exception") after the program's own work is done, so whatever was not disconnected is
# stopped at exit, before finalization.
_RUNNING: weakref.WeakSet[SimBus] = weakref.WeakSet()


@atexit.register
def _disconnect_all() -> None:
    for bus in list(_RUNNING):
        bus.disconnect()


class SimBus:
    """ServoBus on the MuJoCo twin (joint order = the calibrations' order)."""

    carries_load = True  # real or simulated links under gravity (the loop compensates)

    def __init__(self, config: SimBusConfig | None = None) -> None:
        self.config = config or SimBusConfig()
        self.twin = DeltaTwin(self.config.twin)
        self.joints = self.config.twin.joints
        self.ids = tuple(j.servo_id for j in self.joints)
        self.n = len(self.ids)  # three legs, and a wrist when the twin has one
        self.lock = threading.RLock()  # the twin has one owner at a time
        self._rng = np.random.default_rng(self.config.seed)
        self._current_rng = np.random.default_rng(self.config.seed + 1)
        self._stats = BusStats()
        self._connected = False
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.commands = list(self.twin.commands)
        self._goals_to_limits()  # Goal Current = Current Limit at power-on, as the firmware
        if not self.config.torque_on_at_start:
            self._update(torque_enabled=[False] * self.n)

    # -- ServoBus ------------------------------------------------------------------------
    def connect(self) -> None:
        self.disconnect()
        self._connected = True
        if self.config.realtime:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="sim-physics", daemon=True)
            self._thread.start()
            _RUNNING.add(self)

    def disconnect(self) -> None:
        if self._thread is not None:
            self._stop.set()
            self._thread.join(timeout=5.0)
            self._thread = None
        _RUNNING.discard(self)
        self._connected = False

    def scan(self, ids: Sequence[int] | None = None) -> list[ServoInfo]:
        self._require("ping")
        wanted = self.ids if ids is None else ids
        return [
            ServoInfo(i, MODEL_NUMBER_XM430_W210, FIRMWARE_VERSION) for i in wanted if i in self.ids
        ]

    def torque(self, enabled: bool) -> None:
        with self._transaction("write TORQUE_ENABLE"):
            self._shut_down()
            if enabled:
                faulted = {
                    i: hardware_error_names(s.hardware_error)
                    for i, s in self._servos()
                    if s.hardware_error
                }
                if faulted:
                    raise HardwareError(sorted(faulted), "write TORQUE_ENABLE", faulted)
                # hold where the links are, as the driver does: no jump on enable
                ticks = np.round(self.twin.shaft_rad / RAD_PER_TICK) * RAD_PER_TICK
                self._update(goal_position_rad=list(ticks))
            self._update(torque_enabled=[enabled] * self.n)

    def set_operating_mode(self, mode: OperatingMode) -> None:
        with self._transaction("write OPERATING_MODE"):
            on = [i for i, c in zip(self.ids, self.commands, strict=True) if c.torque_enabled]
            if on:
                raise BusError(on, "write OPERATING_MODE", "EEPROM item: turn torque off first")
            self._update(mode=[OperatingMode(mode)] * self.n)
            self._goals_to_limits()  # as the firmware on a mode change

    def set_goal_current(self, currents_a: Sequence[float]) -> None:
        """Goal Current (102) per joint [A], shape (n_joints,), as `DynamixelBus`: each
        rounded to 2.69 mA units and checked against that servo's Current Limit first
        (nothing changes when one is refused); with torque on or off. In Current-based
        Position Control Mode the servo model bounds its current by it.

        Raises ValueError naming the joint, the value and the limit, or for a sequence of
        the wrong length; NotConnectedError.
        """
        with self._transaction("write GOAL_CURRENT"):
            limits = [ampere_to_current(c.current_limit_a) for c in self.commands]
            units = goal_current_units(currents_a, limits, AMPERE_PER_CURRENT_UNIT)
            self._update(goal_current_a=[current_to_ampere(u) for u in units])

    def read_goal_current(self) -> list[float]:
        """Each joint's Goal Current (102) as its servo holds it [A], in joint order."""
        with self._transaction("read GOAL_CURRENT"):
            return [c.goal_current_a for c in self.commands]

    def write_goal(self, positions_rad: Sequence[float]) -> None:
        ticks = goal_ticks(self.joints, positions_rad)
        with self._transaction("sync write GOAL_POSITION"):
            self._update(goal_position_rad=[t * RAD_PER_TICK for t in ticks])

    def read_state(self) -> JointState:
        with self._transaction("sync read MOVING..PRESENT_TEMPERATURE"):
            self._shut_down()
            # the platform at the same instant, for measure_platform(at_last_read=True)
            self._platform_at_read = self.twin.platform_m.copy()
            self._contact_at_read = self.twin.contact()  # and the contact, the same
            return self._state()

    def set_profile(self, velocity_rad_s: float, acceleration_rad_s2: float) -> None:
        # through the register units, so the quantization matches the real servo's (and a
        # positive request below half a unit is 1 unit, never 0 = unlimited)
        units = profile_units(velocity_rad_s, acceleration_rad_s2)
        velocity = velocity_to_rad_s(units[0])
        acceleration = acceleration_to_rad_s2(units[1])
        with self._transaction("write PROFILE"):
            self._update(
                profile_velocity_rad_s=[velocity] * self.n,
                profile_acceleration_rad_s2=[acceleration] * self.n,
            )

    def set_gains(self, gains: PositionGains | Sequence[PositionGains]) -> None:
        each = per_joint(gains, self.n)
        with self._transaction("write POSITION_GAINS"):
            self._update(
                position_p=[g.p for g in each],
                position_i=[g.i for g in each],
                position_d=[g.d for g in each],
                feedforward_1st=[g.feedforward_1st for g in each],
                feedforward_2nd=[g.feedforward_2nd for g in each],
            )

    def read_gains(self) -> list[PositionGains]:
        with self._transaction("read POSITION_GAINS"):
            return [
                PositionGains(
                    c.position_p, c.position_i, c.position_d, c.feedforward_1st, c.feedforward_2nd
                )
                for c in self.commands
            ]

    def reboot(self, ids: Sequence[int] | None = None) -> None:
        targets = set(self.ids if ids is None else ids)
        with self._transaction("reboot"):
            off = [
                i not in targets and c.torque_enabled
                for i, c in zip(self.ids, self.commands, strict=True)
            ]
            for i, servo in self._servos():
                if i in targets:
                    servo.reboot()  # a reboot clears the error and comes back with torque off
            self._update(torque_enabled=off)

    @property
    def stats(self) -> BusStats:
        return self._stats

    # -- beyond the ServoBus protocol --------------------------------------------------
    def advance(self, duration_s: float) -> None:
        """Step the physics by `duration_s` [s] (only without `realtime`)."""
        if self._thread is not None:
            raise RuntimeError("the physics thread owns the clock; advance() is for realtime=False")
        with self.lock:
            self.twin.advance(duration_s)

    def measure_platform(self, at_last_read: bool = False) -> np.ndarray:
        """The external measurement of the platform [m], shape (3,): the true centre plus
        the marker offset, in the measurement frame (the base frame by default), plus noise
        (motion capture's view, `external_measurement`); with ``at_last_read`` at the
        instant of the last read_state (a synchronized capture)."""
        with self.lock:
            true = self.twin.platform_m
            if at_last_read and getattr(self, "_platform_at_read", None) is not None:
                true = self._platform_at_read
        return external_measurement(self.config, true, self._rng)

    def measure_contact(self, at_last_read: bool = False) -> TwinContact:
        """The twin's own contact force: what the tip applies on the plates, base frame
        (`DeltaTwin.contact`: force [N] (3,), point [m] (3,) or None); with
        ``at_last_read`` at the instant of the last read_state. The simulator's truth,
        for tests and benchmarks: no real bus has it."""
        with self.lock:
            if at_last_read and getattr(self, "_contact_at_read", None) is not None:
                return self._contact_at_read
            return self.twin.contact()

    def set_base_motion(self, motion: BaseMotion) -> None:
        """The drone's attitude, acceleration and turning, acting on the arm from now on."""
        with self.lock:
            self.twin.set_base_motion(motion)

    def set_plate_pose(
        self,
        index: int,
        point_m: Sequence[float],
        normal: Sequence[float],
        velocity_m_s: Sequence[float] = (0.0, 0.0, 0.0),
        angular_velocity_rad_s: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> None:
        """Move the twin's plate `index` now (`DeltaTwin.set_plate_pose`: its face point
        [m] and normal, base frame, then moving at [m/s] / turning at [rad/s]). A test's
        or a demonstration's scene change: no real bus has it. Raises ValueError naming
        the index or the field."""
        with self.lock:
            self.twin.set_plate_pose(index, point_m, normal, velocity_m_s, angular_velocity_rad_s)

    # -- internals -----------------------------------------------------------------------
    def _require(self, instruction: str) -> None:
        if not self._connected:
            raise NotConnectedError(self.ids, instruction, "the simulated bus is not connected")

    def _transaction(self, instruction: str):
        self._require(instruction)
        self._stats = replace(self._stats, transactions=self._stats.transactions + 1)
        return self.lock

    def _shut_down(self) -> None:
        """Torque Enable off on each servo that latched an error its Shutdown (63) names,
        as the XM430 does: it then stays off after a reboot until torque() turns it on."""
        on = [c.torque_enabled for c in self.commands]
        kept = [
            t and not s.hardware_error & SHUTDOWN_MASK
            for t, s in zip(on, self.twin.servos, strict=True)
        ]
        if kept != on:
            self._update(torque_enabled=kept)

    def _goals_to_limits(self) -> None:
        """Goal Current := each servo's Current Limit, whole 2.69 mA units (power-on and
        an Operating Mode change, as the firmware)."""
        limits = [ampere_to_current(c.current_limit_a) for c in self.commands]
        self._update(goal_current_a=[current_to_ampere(u) for u in limits])

    def _servos(self):
        return zip(self.ids, self.twin.servos, strict=True)

    def _update(self, **columns: Sequence) -> None:
        """Change fields of every servo's command (one value per servo), under the lock."""
        self.commands = [
            replace(cmd, **{name: values[k] for name, values in columns.items()})
            for k, cmd in enumerate(self.commands)
        ]
        self.twin.set_commands(self.commands)

    def _state(self) -> JointState:
        twin, sign = self.twin, np.array([c.direction for c in self.joints], dtype=float)
        ticks = np.round(twin.shaft_rad / RAD_PER_TICK)
        outputs = twin.outputs
        velocity_units = [rad_s_to_velocity(v) for v in twin.shaft_rad_s]
        velocity = [velocity_to_rad_s(v) for v in velocity_units]
        raw = np.array([o.current_a for o in outputs])
        if self.config.current_noise_a:
            raw = raw + self._current_rng.normal(0.0, self.config.current_noise_a, raw.shape)
        current = [current_to_ampere(ampere_to_current(float(a))) for a in raw]
        # Present Velocity's Moving flag: above Moving Threshold (10 units by default)
        moving = [abs(v) > MOVING_THRESHOLD_UNITS for v in velocity_units]
        return JointState(
            position_rad=np.array(
                [cal.to_rad(t) for cal, t in zip(self.joints, ticks, strict=True)]
            ),
            velocity_rad_s=sign * np.array(velocity),
            current_a=sign * np.array(current),
            voltage_v=np.full(self.n, round(twin.config.servo.supply_voltage_v * 10) / 10),
            temperature_c=np.array([float(round(s.temperature_c)) for s in twin.servos]),
            pwm=sign * np.array([pwm_to_fraction(round(o.pwm)) for o in outputs]),
            moving=np.array(moving),
            hardware_errors=tuple(hardware_error_names(s.hardware_error) for s in twin.servos),
            stamp_s=time.monotonic(),
            sim_time_s=twin.time_s,
            torque_enabled=tuple(c.torque_enabled for c in self.commands),
        )

    def _run(self) -> None:
        """Follow the wall clock: step whatever simulated time is due, then sleep a little."""
        dt = self.twin.model.opt.timestep
        last = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            due = min(now - last, MAX_CATCH_UP_S)
            last = now
            steps = round(due / dt)
            last -= due - steps * dt  # carry the fraction of a step to the next round
            with self.lock:
                self.twin.step(steps)
            # physics in ~2.5 ms chunks: at 1 ms the thread took the GIL 1000 times a second
            # and the control loop's p99 lateness was 0.77 ms; at 2.5 ms it is 0.5-0.6 ms
            # (benchmarks/loop.py --backend sim); 5 ms beats against the 200 Hz loop (0.78 ms)
            self._stop.wait(0.0025)

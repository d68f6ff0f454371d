"""Shaft motion: the interface between a servo's controller and a model of its shaft.

Both rooms below hardware/ use it, so it lives beside them: the emulator (hardware/emulator/)
steps a `MotionModel` between packets, and the simulator (hardware/sim/) provides one. The
emulated bus (hardware/emulator/emulated_bus.py, through stepping.py) turns each servo's
control table into a `MotionCommand`, steps the `MotionModel` by the wall time elapsed since
the last packet, and writes the returned `MotionState` back as Present Position (quantized
to ticks), Velocity and Current. A model sees all servos at once, in the
emulator's servo order, so a model of the coupled mechanism (the MuJoCo twin,
hardware/sim/twin_shaft_motion.py) fits the same interface as the independent
`SimpleServoModel` below. `MotionCommand` is also what the simulator's XM430 model
(hardware/sim/xm430.py) takes.

Angles here are servo shaft angles [rad] = raw ticks * 2 pi / 4096, not calibrated joint
angles: the servo knows nothing of the calibration. A twin maps them through
hardware.calibration.JointCalibration.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from hardware.bus import OperatingMode

MAX_CATCH_UP_S = 0.25


@dataclass(frozen=True)
class MotionCommand:
    """What one servo's control table asks of its motor, in SI units.

    goal_position_rad: Goal Position [rad]; goal_velocity_rad_s: Goal Velocity [rad/s]
    (velocity mode); goal_current_a: Goal Current [A] (current modes);
    profile_velocity_rad_s / profile_acceleration_rad_s2: trajectory limits (0 = none);
    velocity_limit_rad_s / current_limit_a: the EEPROM limits; position_p/i/d and
    feedforward_1st/2nd: raw gain registers (KpP = p / 128 on the XM430).
    """

    torque_enabled: bool
    mode: OperatingMode
    goal_position_rad: float
    goal_velocity_rad_s: float = 0.0
    goal_current_a: float = 0.0
    profile_velocity_rad_s: float = 0.0
    profile_acceleration_rad_s2: float = 0.0
    velocity_limit_rad_s: float = 7.92
    current_limit_a: float = 3.21
    position_p: int = 800
    position_i: int = 0
    position_d: int = 0
    feedforward_1st: int = 0
    feedforward_2nd: int = 0


@dataclass(frozen=True)
class MotionState:
    """One servo's shaft: position [rad], velocity [rad/s] and motor current [A]."""

    position_rad: float
    velocity_rad_s: float
    current_a: float


class MotionModel(Protocol):
    """Plant of all emulated servos. Called from the emulator thread only."""

    def reset(self, positions_rad: Sequence[float]) -> None:
        """Place the shafts at rest at `positions_rad` [rad], one per servo."""

    def step(self, dt_s: float, commands: Sequence[MotionCommand]) -> Sequence[MotionState]:
        """Advance `dt_s` [s] under `commands` (one per servo); return the new states."""


@dataclass(frozen=True)
class SimpleServoParams:
    """Plant of one XM430-W210 with a light link: torque constant, inertia, gain scale.

    torque_constant_nm_a: ~1.3 Nm/A (3.0 Nm stall at 2.3 A, 12 V); inertia_kg_m2: the
    reflected rotor plus an upper link; position_gain_per_s: the position loop's bandwidth
    [1/s] per unit of KpP = p / 128 (default 800 -> 6.25 * 8 = 50/s, a 20 ms time constant);
    substep_s: integration step [s].
    """

    torque_constant_nm_a: float = 1.3
    inertia_kg_m2: float = 0.005
    position_gain_per_s: float = 8.0
    damping_nm_s: float = 0.05
    substep_s: float = 0.0005


class SimpleServoModel:
    """Independent servos: a P position loop on velocity, bounded by the servo's limits.

    Position modes: velocity command = (p / 128) * gain * error, limited by the Velocity
    Limit and the Profile Velocity; its change is limited by the Profile Acceleration and
    by the acceleration the Current Limit allows. Velocity mode tracks Goal Velocity under
    the same limits; current modes apply Goal Current; torque off lets the shaft coast to
    rest under damping. PWM mode is treated as torque off (not modelled).
    """

    def __init__(self, params: SimpleServoParams | None = None) -> None:
        self.params = params or SimpleServoParams()
        self._states: list[MotionState] = []

    def reset(self, positions_rad: Sequence[float]) -> None:
        self._states = [MotionState(float(p), 0.0, 0.0) for p in positions_rad]

    def step(self, dt_s: float, commands: Sequence[MotionCommand]) -> Sequence[MotionState]:
        if len(commands) != len(self._states):
            raise ValueError(f"{len(commands)} commands for {len(self._states)} servos")
        remaining = max(0.0, dt_s)
        # Cap the catch-up so the first packet after an idle gap costs bounded CPU: emulated
        # time runs slow across gaps longer than MAX_CATCH_UP_S, never fast.
        remaining = min(remaining, MAX_CATCH_UP_S)
        while remaining > 1e-9:
            h = min(self.params.substep_s, remaining)
            pairs = zip(self._states, commands, strict=True)
            self._states = [self._substep(h, s, c) for s, c in pairs]
            remaining -= h
        return list(self._states)

    def _substep(self, h: float, state: MotionState, cmd: MotionCommand) -> MotionState:
        p = self.params
        v = state.velocity_rad_s
        if not cmd.torque_enabled or cmd.mode == OperatingMode.PWM:
            accel = -p.damping_nm_s * v / p.inertia_kg_m2
            v_new = v + accel * h if abs(accel * h) < abs(v) else 0.0
            return MotionState(state.position_rad + v_new * h, v_new, 0.0)
        if cmd.mode == OperatingMode.CURRENT:
            current = max(-cmd.current_limit_a, min(cmd.current_limit_a, cmd.goal_current_a))
            accel = (p.torque_constant_nm_a * current - p.damping_nm_s * v) / p.inertia_kg_m2
            v_new = v + accel * h
            return MotionState(state.position_rad + v_new * h, v_new, current)
        v_target = self._velocity_target(state, cmd)
        accel = (v_target - v) / h
        a_max = math.inf
        if cmd.profile_acceleration_rad_s2 > 0:
            a_max = cmd.profile_acceleration_rad_s2
        accel = max(-a_max, min(a_max, accel))
        # The motor supplies inertia plus damping torque, within the Current Limit (and in
        # Current-based Position Control Mode within the Goal Current, as the firmware).
        bound = cmd.current_limit_a
        if cmd.mode == OperatingMode.CURRENT_BASED_POSITION:
            bound = min(bound, abs(cmd.goal_current_a))
        current = (p.inertia_kg_m2 * accel + p.damping_nm_s * v) / p.torque_constant_nm_a
        current = max(-bound, min(bound, current))
        accel = (p.torque_constant_nm_a * current - p.damping_nm_s * v) / p.inertia_kg_m2
        v_new = v + accel * h
        return MotionState(state.position_rad + v_new * h, v_new, current)

    def _velocity_target(self, state: MotionState, cmd: MotionCommand) -> float:
        v_max = cmd.velocity_limit_rad_s
        if cmd.profile_velocity_rad_s > 0:
            v_max = min(v_max, cmd.profile_velocity_rad_s)
        if cmd.mode == OperatingMode.VELOCITY:
            target = cmd.goal_velocity_rad_s
        else:
            error = cmd.goal_position_rad - state.position_rad
            target = (cmd.position_p / 128.0) * self.params.position_gain_per_s * error
            # Never overshoot within one substep: the discrete loop must stay stable.
            target = math.copysign(min(abs(target), abs(error) / self.params.substep_s), error)
        return max(-v_max, min(v_max, target))

"""Stepping the shafts: emulated control tables -> MotionModel -> present values back.

Each step reads every servo's goal, limit, profile and gain items, converts them to SI
units (hardware/dynamixel/control_table.py), steps the model, and writes Present Position
(quantized to ticks), Velocity, Current, Moving and the trajectory items back into the tables.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from hardware.dynamixel.control_table import (
    RAD_PER_TICK,
    OperatingMode,
    Reg,
    acceleration_to_rad_s2,
    ampere_to_current,
    current_to_ampere,
    rad_s_to_velocity,
    velocity_to_rad_s,
)
from hardware.emulator.emulated_servo import EmulatedServo
from hardware.shaft_motion import MotionCommand, MotionModel, MotionState

INPUT_VOLTAGE_UNITS = 120  # 12.0 V supply
TEMPERATURE_C = 30


# Bytes 11 .. 119 hold every item a MotionCommand depends on (mode, limits, torque, gains,
# goals, profiles) but the servo's turn count; rebuilding the command only when they change
# keeps the emulator fast.
_COMMAND_BYTES = slice(Reg.OPERATING_MODE.address, Reg.GOAL_POSITION.address + 4)


def command_of(servo: EmulatedServo) -> MotionCommand:
    """The MotionCommand one servo's control table expresses (cached per table contents)."""
    key = (bytes(servo.table.memory[_COMMAND_BYTES]), servo.turn_ticks)
    cached = servo.command_cache
    if cached is not None and cached[0] == key:
        return cached[1]  # type: ignore[return-value]
    command = _build_command(servo)
    servo.command_cache = (key, command)
    return command


def _build_command(servo: EmulatedServo) -> MotionCommand:
    t = servo.table
    mode = t.get(Reg.OPERATING_MODE)
    return MotionCommand(
        torque_enabled=t.get(Reg.TORQUE_ENABLE) == 1,
        mode=OperatingMode(mode) if mode in OperatingMode._value2member_map_ else OperatingMode.PWM,
        # Present Position = shaft + the offset in force, so the shaft's goal is the goal minus it.
        goal_position_rad=(t.get(Reg.GOAL_POSITION) - servo.present_offset) * RAD_PER_TICK,
        goal_velocity_rad_s=velocity_to_rad_s(t.get(Reg.GOAL_VELOCITY)),
        goal_current_a=current_to_ampere(t.get(Reg.GOAL_CURRENT)),
        profile_velocity_rad_s=velocity_to_rad_s(t.get(Reg.PROFILE_VELOCITY)),
        profile_acceleration_rad_s2=acceleration_to_rad_s2(t.get(Reg.PROFILE_ACCELERATION)),
        velocity_limit_rad_s=velocity_to_rad_s(t.get(Reg.VELOCITY_LIMIT)),
        current_limit_a=current_to_ampere(t.get(Reg.CURRENT_LIMIT)),
        position_p=t.get(Reg.POSITION_P_GAIN),
        position_i=t.get(Reg.POSITION_I_GAIN),
        position_d=t.get(Reg.POSITION_D_GAIN),
        feedforward_1st=t.get(Reg.FEEDFORWARD_1ST_GAIN),
        feedforward_2nd=t.get(Reg.FEEDFORWARD_2ND_GAIN),
    )


# Moving 122 .. Present Temperature 146 in one pack: Moving, Moving Status, Present PWM,
# Current, Velocity, Position, Velocity Trajectory, Position Trajectory, Voltage, Temperature.
_PRESENT = struct.Struct("<BBhhiiiiHB")
_PRESENT_START = Reg.MOVING.address


def store_state(servo: EmulatedServo, state: MotionState, now_s: float) -> None:
    """Write a model state into the servo's present-value items."""
    t = servo.table
    velocity = rad_s_to_velocity(state.velocity_rad_s)
    limit = t.get(Reg.CURRENT_LIMIT)
    current = max(-limit, min(limit, ampere_to_current(state.current_a)))
    moving = int(abs(velocity) > t.get(Reg.MOVING_THRESHOLD))
    # Clamped to the register's int32 so a runaway model cannot crash the emulator thread.
    shaft = round(state.position_rad / RAD_PER_TICK)
    position = max(-(2**31), min(2**31 - 1, shaft + servo.present_offset))
    goal = t.get(Reg.GOAL_POSITION)
    _PRESENT.pack_into(
        t.memory,
        _PRESENT_START,
        moving,
        0,  # Moving Status: profile details are not modelled
        t.get(Reg.PRESENT_PWM),  # Present PWM: a physical model's (_store_outputs), else 0
        current,
        velocity,
        position,
        velocity,
        goal,
        INPUT_VOLTAGE_UNITS,
        TEMPERATURE_C,
    )
    t.set(Reg.REALTIME_TICK, int(now_s * 1000) % 32768)


def advance_servos(
    model: MotionModel, servos: Sequence[EmulatedServo], dt_s: float, now_s: float
) -> None:
    """Step `model` by `dt_s` [s] under the servos' tables and store the results."""
    states = model.step(dt_s, [command_of(servo) for servo in servos])
    for servo, state in zip(servos, states, strict=True):
        store_state(servo, state, now_s)
    outputs = getattr(model, "outputs", None)  # models of the servo's heat and protection
    if outputs is not None:
        _store_outputs(model, servos, outputs)


def _store_outputs(model: MotionModel, servos: Sequence[EmulatedServo], outputs) -> None:
    """Temperature and latched errors from a physical model (the twin) into the tables;
    a Reboot the servo has executed since clears the model's latched error too."""
    for index, (servo, output) in enumerate(zip(servos, outputs, strict=True)):
        if getattr(servo, "model_reboots", 0) != servo.reboots:
            model.reboot(index)  # type: ignore[attr-defined]
            servo.model_reboots = servo.reboots  # type: ignore[attr-defined]
        servo.table.set(Reg.PRESENT_TEMPERATURE, max(0, min(100, round(output.temperature_c))))
        limit = servo.table.get(Reg.PWM_LIMIT)
        servo.table.set(Reg.PRESENT_PWM, max(-limit, min(limit, round(output.pwm))))
        # latch what the model newly reports; its outputs lag a reboot by one physics step
        seen = getattr(servo, "model_error_seen", 0)
        if output.hardware_error and output.hardware_error != seen:
            servo.raise_hardware_error(output.hardware_error)
        servo.model_error_seen = output.hardware_error  # type: ignore[attr-defined]

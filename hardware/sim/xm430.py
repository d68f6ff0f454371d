"""A physical model of the ROBOTIS XM430-W210: firmware position loop, PWM, DC motor, heat.

One servo, stepped at the firmware's control period with the shaft's angle and speed from
whatever moves the shaft (the MuJoCo twin, or the emulator through a MotionModel):

1. Encoder: the shaft angle read as whole ticks (4096 per turn), as the firmware sees it.
2. Profile (hardware.sim.xm430_profile): Goal Position shaped by Profile Velocity and
   Acceleration into a desired position, velocity and acceleration.
3. Position PID with feed-forward, in control-table units as the e-manual documents them:
   PWM = KpP e + KiP sum(e) + KdP de + KFF1 v_d + KFF2 a_d, KpP = P / 128, KiP = I / 65536,
   KdP = D / 16, KFF = FF / 4; e in ticks, rates in ticks per control period (an
   assumption: ROBOTIS documents the scalings but not the time base). Clamped to the PWM
   Limit (885 = 100 %).
4. Motor: terminal voltage = PWM / 885 * input voltage; current i = (V - Ke w) / R (in
   Current-based Position Control Mode the PWM is first clamped so that
   |i| <= min(|Goal Current|, Current Limit), as the firmware bounds it); output
   torque Kt i (the gearbox's dry friction is applied by whatever moves the shaft).
   R, Kt and Ke come from the datasheet's torque-speed line
   (stall torque and current, no-load speed, all at the rated voltage), so the available
   torque falls with speed exactly along that line.
5. Heat: a first-order winding temperature driven by i^2 R; Overheating trips at the
   Temperature Limit, Overload when the output stays saturated longer than overload_time_s.
   A tripped servo drops torque until rebooted, as the real one does (Shutdown defaults).

Angles are shaft angles [rad] (ticks * 2 pi / 4096), not calibrated joint angles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from hardware.dynamixel.control_table import (
    PWM_FULL_SCALE,
    RAD_PER_TICK,
    RAD_S_PER_VELOCITY_UNIT,
    HardwareErrorFlag,
    OperatingMode,
)
from hardware.shaft_motion import MotionCommand
from hardware.sim.xm430_profile import ProfileState, step_profile

RPM = 2.0 * math.pi / 60.0
_POSITION_MODES = (
    OperatingMode.POSITION,
    OperatingMode.EXTENDED_POSITION,
    OperatingMode.CURRENT_BASED_POSITION,
)


@dataclass(frozen=True)
class Xm430Params:
    """Datasheet and firmware constants of one XM430-W210 (defaults: ROBOTIS, at 12 V).

    stall_torque_nm / stall_current_a / no_load_speed_rad_s at rated_voltage_v define the
    motor's line; supply_voltage_v is what the servo is powered with. pwm_limit: PWM Limit
    (36). control_period_s: the firmware loop period [s] (not published; 1 ms assumed).
    coulomb_friction_nm: gearbox dry friction at the output (an estimate, not published);
    the twin applies it as MuJoCo joint frictionloss, which sticks at rest as real friction
    does (a smooth friction law in this explicit loop creeps instead). Thermal: steady rise
    thermal_resistance_k_w [K/W] with time constant thermal_time_constant_s [s] (estimates);
    temperature_limit_c: Temperature Limit (31). overload_time_s: how long the output may
    stay saturated before Overload trips (ROBOTIS does not publish it; estimate).
    velocity_p_gain / velocity_i_gain: Velocity P/I Gain (78/76) for velocity mode.
    """

    stall_torque_nm: float = 3.0
    stall_current_a: float = 2.3
    no_load_speed_rad_s: float = 77.0 * RPM
    rated_voltage_v: float = 12.0
    supply_voltage_v: float = 12.0
    pwm_limit: int = 885
    control_period_s: float = 0.001
    coulomb_friction_nm: float = 0.02
    ambient_c: float = 25.0
    thermal_resistance_k_w: float = 4.0
    thermal_time_constant_s: float = 120.0
    temperature_limit_c: float = 80.0
    overload_time_s: float = 1.5
    velocity_p_gain: int = 100
    velocity_i_gain: int = 1920

    def __post_init__(self) -> None:
        positive = ("stall_torque_nm", "stall_current_a", "no_load_speed_rad_s", "control_period_s")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} = {getattr(self, name)!r}: must be > 0")
        if not 0 <= self.pwm_limit <= PWM_FULL_SCALE:
            raise ValueError(f"pwm_limit = {self.pwm_limit}: must be within 0..{PWM_FULL_SCALE}")

    @property
    def resistance_ohm(self) -> float:
        """Winding resistance [ohm]: rated voltage over stall current."""
        return self.rated_voltage_v / self.stall_current_a

    @property
    def torque_constant_nm_a(self) -> float:
        """Output torque per ampere [N m / A], gearbox losses included."""
        return self.stall_torque_nm / self.stall_current_a

    @property
    def back_emf_v_s(self) -> float:
        """Back-EMF per output speed [V s / rad]: rated voltage over no-load speed."""
        return self.rated_voltage_v / self.no_load_speed_rad_s


XM430_W210 = Xm430Params()


class ServoOutput(NamedTuple):
    """One control period's result: output torque [N m] on the shaft, motor current [A],
    PWM [register units, +-885], winding temperature [degC], Hardware Error Status bits."""

    torque_nm: float
    current_a: float
    pwm: float
    temperature_c: float
    hardware_error: int


class Xm430:
    """One XM430-W210: its firmware state, its motor and its temperature."""

    def __init__(self, params: Xm430Params = XM430_W210, shaft_rad: float = 0.0) -> None:
        self.params = params
        # derived constants, computed once: step() runs 3000 times per simulated second
        self._volt_per_pwm = params.supply_voltage_v / PWM_FULL_SCALE
        self._ke, self._kt = params.back_emf_v_s, params.torque_constant_nm_a
        self._ohm = params.resistance_ohm
        self._mode_cache: tuple[OperatingMode, str] | None = None
        self.temperature_c = params.ambient_c
        self.hardware_error = 0
        self.reset(shaft_rad)

    def reset(self, shaft_rad: float) -> None:
        """Controller state at rest at `shaft_rad` [rad] (temperature and errors are kept)."""
        self.profile = ProfileState(shaft_rad, 0.0, 0.0)
        self._integral = 0.0
        self._velocity_integral = 0.0
        self._last_error: float | None = None
        self._saturated_s = 0.0
        self.last = ServoOutput(0.0, 0.0, 0.0, self.temperature_c, self.hardware_error)

    def reboot(self) -> None:
        """Clear the latched Hardware Error Status, as the Reboot instruction does."""
        self.hardware_error = 0
        self._saturated_s = 0.0

    def step(self, cmd: MotionCommand, shaft_rad: float, shaft_rad_s: float) -> ServoOutput:
        """Advance one control period under `cmd` with the shaft at `shaft_rad` [rad] moving
        at `shaft_rad_s` [rad/s]; returns the torque to apply until the next period."""
        p = self.params
        ticks = round(shaft_rad / RAD_PER_TICK)  # the encoder
        live = cmd.torque_enabled and not self.hardware_error
        kind = self._kind(cmd.mode)
        if not live:
            self.reset(ticks * RAD_PER_TICK)
            pwm = 0.0
        elif kind == "position":
            pwm = self._position_pwm(cmd, ticks)
        elif kind == "velocity":
            pwm = self._velocity_pwm(cmd, shaft_rad_s)
        elif kind == "current":
            pwm = self._current_pwm(cmd.goal_current_a, shaft_rad_s)
        else:  # PWM mode: Goal PWM is not part of MotionCommand, so the output is idle
            pwm = 0.0
        if live and cmd.mode is OperatingMode.CURRENT_BASED_POSITION:
            # the firmware's bound: |Goal Current|, itself never above the Current Limit
            bound = min(abs(cmd.goal_current_a), cmd.current_limit_a)
            pwm = self._limit_current(pwm, bound, shaft_rad_s)
        limit = p.pwm_limit
        pwm = -limit if pwm < -limit else (limit if pwm > limit else pwm)
        current = 0.0
        if live:  # torque off opens the bridge: no current, no back-EMF braking
            current = (pwm * self._volt_per_pwm - self._ke * shaft_rad_s) / self._ohm
        self._heat(current, live and abs(pwm) >= limit)
        self.last = ServoOutput(
            self._kt * current, current, pwm, self.temperature_c, self.hardware_error
        )
        return self.last

    def _kind(self, mode: OperatingMode) -> str:
        """position | velocity | current | pwm; cached, as enum hashing is slow per step."""
        cached = self._mode_cache
        if cached is not None and cached[0] is mode:
            return cached[1]
        kind = (
            "position"
            if mode in _POSITION_MODES
            else {OperatingMode.VELOCITY: "velocity", OperatingMode.CURRENT: "current"}.get(
                mode, "pwm"
            )
        )
        self._mode_cache = (mode, kind)
        return kind

    def _position_pwm(self, cmd: MotionCommand, ticks: int) -> float:
        p = self.params
        self.profile = step_profile(self.profile, cmd, p.control_period_s)
        dt = p.control_period_s
        per_period = dt / RAD_PER_TICK  # rad/s -> ticks per period
        error = self.profile.position_rad / RAD_PER_TICK - ticks
        self._integral += error
        # anti-windup: the integral term alone never asks for more than the PWM limit
        if cmd.position_i > 0:
            bound = p.pwm_limit * 65536.0 / cmd.position_i
            self._integral = max(-bound, min(bound, self._integral))
        rate = 0.0 if self._last_error is None else error - self._last_error
        self._last_error = error
        return (
            cmd.position_p / 128.0 * error
            + cmd.position_i / 65536.0 * self._integral
            + cmd.position_d / 16.0 * rate
            + cmd.feedforward_1st / 4.0 * self.profile.velocity_rad_s * per_period
            + cmd.feedforward_2nd / 4.0 * self.profile.acceleration_rad_s2 * dt * per_period
        )

    def _velocity_pwm(self, cmd: MotionCommand, shaft_rad_s: float) -> float:
        limit = cmd.velocity_limit_rad_s
        goal = max(-limit, min(limit, cmd.goal_velocity_rad_s))
        error = (goal - shaft_rad_s) / RAD_S_PER_VELOCITY_UNIT  # in 0.229 rpm units
        self._velocity_integral += error
        p = self.params
        integral = self._velocity_integral
        return p.velocity_p_gain / 128.0 * error + p.velocity_i_gain / 65536.0 * integral

    def _current_pwm(self, current_a: float, shaft_rad_s: float) -> float:
        """The PWM whose current is `current_a` at this speed (an ideal current loop)."""
        p = self.params
        volts = current_a * p.resistance_ohm + p.back_emf_v_s * shaft_rad_s
        return volts / p.supply_voltage_v * PWM_FULL_SCALE

    def _limit_current(self, pwm: float, limit_a: float, shaft_rad_s: float) -> float:
        """`pwm` clamped so that the motor current at this speed stays within +-`limit_a`
        [A] (Current-based Position Control Mode: an ideal current limiter)."""
        high = self._current_pwm(limit_a, shaft_rad_s)
        low = self._current_pwm(-limit_a, shaft_rad_s)
        return max(low, min(high, pwm))

    def _heat(self, current_a: float, saturated: bool) -> None:
        p = self.params
        dt = p.control_period_s
        rise = current_a * current_a * self._ohm * p.thermal_resistance_k_w
        relax = dt / p.thermal_time_constant_s
        self.temperature_c += (p.ambient_c + rise - self.temperature_c) * relax
        if saturated:
            self._saturated_s += dt
            if self._saturated_s > p.overload_time_s:
                self.hardware_error |= int(HardwareErrorFlag.OVERLOAD)
        else:
            self._saturated_s = 0.0
        if self.temperature_c >= p.temperature_limit_c:
            self.hardware_error |= int(HardwareErrorFlag.OVERHEATING)

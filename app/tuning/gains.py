"""Position-loop gains from an identified joint model, and what they are predicted to do.

The plant. `identify.JointModel` is the joint's closed loop under the gains it was
identified with (P only, ``p_identified``, the factory 800): K wn^2 / (s^2 + 2 zeta wn s +
wn^2). With P only that loop is Kp0 g / (s (s + a)) closed by unity feedback, Kp0 the
firmware's PWM per rad of error (P / 128 in ticks), so the motor and arm seen from the PWM
are

    G(s) = g e^{-s tau} / (s (s + a)),   g = wn^2 / Kp0 [rad/s^2 per PWM],  a = 2 zeta wn [1/s]

(J y'' + b y' = c PWM with a = b / J, g = c / J; app/control/gravity.py for c). tau is the
delay inside the position loop: the firmware's period (``inner_delay_s``, 1 ms). The model's
delay T is the command path's (bus, the loop's tick, the hold): it lies outside the
servo's loop, so it delays the response but does not limit the loop's stability.

The rule (`suggest`), for a target closed-loop bandwidth f_t [Hz], a phase-margin floor
PM_min and an overshoot limit:

1. D cancels the mechanical pole: the PD zero at s = -a, Kd = Kp / a. The open loop is then
   an integrator, L = (Kp g / a) e^{-s tau} / s, crossing over at wc = Kp g / a, with no
   overshoot of its own (a first-order closed loop, bandwidth ~wc).
2. P for the target: wc = 2 pi f_t, Kp = a wc / g, lowered until the phase margin
   90 deg - wc tau - atan(wi / wc) is at least PM_min.
3. I for zero static error (the sag under gravity): the PI zero well below the crossover,
   wi = wc / 40, Ki = Kp wi. A PI zero at wi under an integrator loop leaves a slow
   closed-loop pole near it whose residue, about wi / wc, is the step's overshoot: 1/40
   keeps it near 2.5 % (a decade, the textbook choice, overshoots 13 %); it costs
   atan(1/40) = 1.4 deg of margin, and the sag then decays with a time constant ~40 / wc.
4. FF1 / FF2: the model's own velocity and acceleration gains, the PWM that moves the
   plant along a path without error: PWM = (y'' + a y') / g, so kv = a / g, ka = 1 / g.
   The firmware applies them to its Profile's velocity and acceleration (zero while the
   Profile is unlimited, as the loop leaves it), so they do not enter the prediction.
   Off by default (``Target.feedforward``): with the Profile off they act on nothing, and
   with a Profile the servos' FF1 / FF2 tracked the thesis sinusoid worse than the loop's
   lead time on the twin, FF2 putting the PWM at its limit 10-80 % of the run
   (docs/performance.md, "The servos' feed-forward against the loop's lead").
5. Each gain to its register: P = 128 Kp / n, I = 65536 Ki dt / n, D = 16 Kd / (n dt),
   FF1 = 4 kv / (n dt), FF2 = 4 ka / (n dt^2) (n = 4096 / 2 pi ticks per rad, dt the
   firmware period; the e-manual's KpP = P / 128, KiP = I / 65536, KdP = D / 16, KFF = FF / 4
   on errors in ticks and rates per period, as hardware/sim/xm430.py models them), rounded
   and clipped to the XM430's limits 0..16383.
6. D is capped by the encoder's quantisation. The firmware's D term is D / 16 times the
   error's change per period in whole ticks (hardware/sim/xm430.py: PWM = P/128 e +
   I/65536 sum e + D/16 (e_k - e_{k-1}) + ...), so one tick of velocity noise (the encoder
   stepping by one tick between two periods, which it does at any speed that is not a
   whole number of ticks per period, and at rest at a tick's edge) is a PWM jump of D / 16.
   That jump must leave the PWM headroom the target keeps: D / 16 * 1 tick <=
   (1 - pwm_fraction) * 885, i.e. D <= 16 (1 - pwm_fraction) 885 (2832 at the default 0.8;
   `d_limit`). When the cap binds, D no longer cancels the pole, the PD loop's damping is
   (a + g Kd) / (2 sqrt(g Kp)), and the check below lowers wc (hence Kp) until the step's
   overshoot is back within the limit.
7. Checked (`predict`) with the clipped registers: the open loop's crossover and phase
   margin, the closed loop's -3 dB bandwidth, and a simulated step of ``step_rad`` through
   the firmware's discrete PID at dt with its PWM limit and its encoder (the error in whole
   ticks, so the D cap's loss of damping and the tick's limit cycle both show in the
   overshoot), peak PWM. While the
   overshoot exceeds the limit, the PI zero moves down (wc / 80, / 160, / 320: a weaker
   I, a smaller residue); if none passes, or the step's peak PWM is over the target's
   headroom, wc is lowered by 15 % and the rule repeats.
8. Once a lowered wc passes, the step between it and the last that failed is halved
   (geometrically) three times: wc is then within 2 % of the boundary (1.176^(1/8)), not
   15 % (the 15 % steps went from P 912 to P 1073 for the twin's joints with no D, and
   missed the P ~1000 between that passes on the twin).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from app.tuning.identify import JointModel
from hardware.bus import PositionGains

TICKS_PER_RAD = 4096 / (2 * math.pi)
FIRMWARE_PERIOD_S = 0.001  # the XM430's control period (hardware/sim/xm430.py)
PWM_LIMIT = 885  # PWM Limit's maximum (100 %)
REGISTER_MAX = 16383  # Position P/I/D and Feedforward 1st/2nd gains: 0..16383 (e-manual)
INTEGRAL_RATIOS = (40.0, 80.0, 160.0, 320.0)  # the PI zero this far below the crossover
SHRINK = 0.85  # the crossover's step down while a check fails
TRIES = 40
REFINE = 3  # halvings of the last step down (rule 8): 0.85^(1/8), a 2 % resolution


class TuningError(ValueError):
    """A target or model that cannot give gains (the message names the field)."""


@dataclass(frozen=True)
class Target:
    """What the gains aim at: bandwidth_hz [Hz] of the closed position loop,
    phase_margin_deg [deg] at least, overshoot_pct [%] at most for a step of step_rad [rad]
    (the run's 4 mm step is ~0.02 rad) using at most pwm_fraction of the PWM limit,
    feedforward: suggest FF1 / FF2 (else 0, the default: the loop's lead time is the
    better feed-forward, module rule 4), integral: suggest I (else 0, the sag at rest
    left to the loop's gravity offset, app/control/gravity.py). Raises TuningError naming a
    field out of range."""

    bandwidth_hz: float = 20.0
    phase_margin_deg: float = 60.0
    overshoot_pct: float = 5.0
    step_rad: float = 0.02
    pwm_fraction: float = 0.8
    feedforward: bool = False
    integral: bool = True

    def __post_init__(self) -> None:
        checks = (
            ("bandwidth_hz", 0.1 <= self.bandwidth_hz <= 100.0, "0.1..100 Hz"),
            ("phase_margin_deg", 20.0 <= self.phase_margin_deg <= 85.0, "20..85 deg"),
            ("overshoot_pct", 0.0 < self.overshoot_pct <= 50.0, "0..50 %"),
            ("step_rad", 0.0 < self.step_rad <= 0.5, "0..0.5 rad"),
            ("pwm_fraction", 0.05 <= self.pwm_fraction <= 1.0, "0.05..1"),
        )
        for name, ok, allowed in checks:
            if not (ok and math.isfinite(getattr(self, name))):
                raise TuningError(f"{name} = {getattr(self, name)!r}: must be in {allowed}")


@dataclass(frozen=True)
class Plant:
    """G(s) = g e^{-s tau} / (s (s + a)) from PWM to joint angle: g [rad/s^2 per PWM unit],
    a [1/s], tau_s [s] (the delay inside the position loop)."""

    g: float
    a: float
    tau_s: float

    @classmethod
    def of(
        cls,
        model: JointModel,
        p_identified: int = PositionGains().p,
        inner_delay_s: float = FIRMWARE_PERIOD_S,
    ) -> Plant:
        """The plant a model fitted under P = `p_identified` (I = D = 0) implies (module
        docstring). Raises TuningError for a gain that is not positive."""
        if p_identified <= 0:
            raise TuningError(f"p_identified = {p_identified}: must be > 0")
        kp0 = p_identified / 128.0 * TICKS_PER_RAD
        return cls(model.wn_rad_s**2 / kp0, 2.0 * model.zeta * model.wn_rad_s, inner_delay_s)


def continuous(gains: PositionGains) -> tuple[float, float, float]:
    """The registers as Kp [PWM/rad], Ki [PWM/(rad s)], Kd [PWM/(rad/s)] (module rule 5)."""
    n, dt = TICKS_PER_RAD, FIRMWARE_PERIOD_S
    return gains.p / 128.0 * n, gains.i / 65536.0 * n / dt, gains.d / 16.0 * n * dt


def _register(value: float) -> int:
    return int(min(max(round(value), 0), REGISTER_MAX))


def d_limit(pwm_fraction: float) -> int:
    """The largest Position D Gain register whose response to one tick of velocity noise,
    D / 16 [PWM per tick per period] (the firmware's KdP = D / 16 on the error's change in
    ticks per period), stays within the headroom above `pwm_fraction` of the PWM limit:
    floor(16 (1 - pwm_fraction) 885) (module rule 6). 2832 at 0.8."""
    return min(int(math.floor(16.0 * (1.0 - pwm_fraction) * PWM_LIMIT + 1e-9)), REGISTER_MAX)


def registers(kp: float, ki: float, kd: float, kv: float, ka: float) -> PositionGains:
    """Continuous gains (PWM per rad, rad s, rad/s, rad/s, rad/s^2) as the XM430's
    registers, rounded and clipped to 0..16383 (module rule 5)."""
    n, dt = TICKS_PER_RAD, FIRMWARE_PERIOD_S
    return PositionGains(
        p=_register(128.0 * kp / n),
        i=_register(65536.0 * ki * dt / n),
        d=_register(16.0 * kd / (n * dt)),
        feedforward_1st=_register(4.0 * kv / (n * dt)),
        feedforward_2nd=_register(4.0 * ka / (n * dt * dt)),
    )


@dataclass(frozen=True)
class Prediction:
    """What gains do on a plant: crossover_hz [Hz] and phase_margin_deg [deg] of the open
    loop, bandwidth_hz [Hz] (-3 dB) and peak_db [dB] of the closed loop, and of a simulated
    step: overshoot_pct [%], settling_s [s] (to within 2 %), peak_pwm_fraction (of the PWM
    limit), static_error_pct [%] (the mean error over the step's last tenth)."""

    crossover_hz: float
    phase_margin_deg: float
    bandwidth_hz: float
    peak_db: float
    overshoot_pct: float
    settling_s: float
    peak_pwm_fraction: float
    static_error_pct: float

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}


FREQS_HZ = np.geomspace(0.05, 400.0, 4000)


def predict(plant: Plant, gains: PositionGains, step_rad: float = 0.02) -> Prediction:
    """The loop's margins and bandwidth from C(s) G(s), C = Kp + Ki / s + Kd s (the
    registers' `continuous` gains), on a grid of 0.05..400 Hz; and `step_s` of a step of
    `step_rad` [rad] simulated through the firmware's PID (errors in ticks, its sum and
    per-period difference, PWM clipped to +-885) at its period, the plant integrated in 10
    sub-steps per period with the PWM delayed by tau. Infinite margins and NaN bandwidth
    where the loop never crosses over."""
    kp, ki, kd = continuous(gains)
    s = 2j * math.pi * FREQS_HZ
    loop = (kp + ki / s + kd * s) * plant.g * np.exp(-s * plant.tau_s) / (s * (s + plant.a))
    closed = np.abs(loop / (1.0 + loop))
    above = np.nonzero(np.abs(loop) >= 1.0)[0]
    if above.size and above[-1] + 1 < FREQS_HZ.size:
        k = above[-1]
        crossover = float(FREQS_HZ[k])
        margin = float(180.0 + np.degrees(np.angle(loop[k])))
        margin = (margin + 180.0) % 360.0 - 180.0
    else:
        crossover, margin = math.nan, math.inf
    below = np.nonzero(closed < 1 / math.sqrt(2))[0]
    bandwidth = float(FREQS_HZ[below[0]]) if below.size else math.nan
    # long enough for the integral's slow mode (time constant ~Kp / Ki) to settle
    duration = STEP_S if ki <= 0 else min(max(STEP_S, 6.0 * kp / ki), 4.0)
    step = simulate_step(plant, gains, step_rad, duration)
    return Prediction(crossover, margin, bandwidth, float(20 * np.log10(closed.max())), *step)


STEP_S = 0.6


def simulate_step(
    plant: Plant, gains: PositionGains, step_rad: float, duration_s: float = STEP_S
) -> tuple[float, float, float, float]:
    """(overshoot_pct, settling_s, peak_pwm_fraction, static_error_pct) of a step of
    `step_rad` [rad] at t = 0 through the firmware's discrete PID (`predict`)."""
    dt, sub = FIRMWARE_PERIOD_S, 10
    h = dt / sub
    delay = max(round(plant.tau_s / dt), 0)
    goal = float(round(step_rad * TICKS_PER_RAD))  # Goal Position: whole ticks
    y = v = integral = 0.0
    last_error: float | None = None
    pwm_queue = [0.0] * delay
    out, peak = [], 0.0
    for _ in range(round(duration_s / dt)):
        error = goal - round(y * TICKS_PER_RAD)  # the encoder: whole ticks
        integral += error
        if gains.i > 0:  # the firmware's anti-windup (hardware/sim/xm430.py)
            bound = PWM_LIMIT * 65536.0 / gains.i
            integral = max(-bound, min(bound, integral))
        rate = 0.0 if last_error is None else error - last_error
        last_error = error
        pwm = gains.p / 128.0 * error + gains.i / 65536.0 * integral + gains.d / 16.0 * rate
        pwm = max(-PWM_LIMIT, min(PWM_LIMIT, pwm))
        peak = max(peak, abs(pwm))
        pwm_queue.append(pwm)
        applied = pwm_queue.pop(0)
        for _ in range(sub):  # semi-implicit Euler
            v += h * (plant.g * applied - plant.a * v)
            y += h * v
        out.append(y)
    response = np.array(out) / step_rad
    overshoot = max(0.0, float(response.max()) - 1.0) * 100.0
    outside = np.nonzero(np.abs(response - 1.0) > 0.02)[0]
    settling = (outside[-1] + 1) * dt if outside.size else 0.0
    if outside.size and outside[-1] == response.size - 1:
        settling = math.inf
    tail = response[-max(response.size // 10, 1) :]
    return overshoot, settling, peak / PWM_LIMIT, float(abs(1.0 - tail.mean()) * 100.0)


@dataclass(frozen=True)
class Suggestion:
    """Gains for one joint: the registers, the target's crossover actually used
    (crossover_hz [Hz]), the prediction with them, and whether it meets the target
    (overshoot under the limit and margin over the floor)."""

    gains: PositionGains
    crossover_hz: float
    prediction: Prediction
    meets_target: bool


def gains_at(plant: Plant, target: Target, crossover_hz: float) -> Suggestion:
    """The rule's gains for `plant` at one crossover `crossover_hz` [Hz] (module rules
    1-7 without the search over wc): the PI zero moved down while the predicted step
    overshoots, and whether the result meets `target`."""
    wc = 2 * math.pi * crossover_hz
    d_cap = d_limit(target.pwm_fraction)
    kv, ka = (plant.a / plant.g, 1.0 / plant.g) if target.feedforward else (0.0, 0.0)
    kp = plant.a * wc / plant.g
    result: Suggestion | None = None
    for ratio in INTEGRAL_RATIOS:
        ki = kp * wc / ratio if target.integral else 0.0
        gains = registers(kp, ki, kp / plant.a, kv, ka)
        gains = replace(gains, d=min(gains.d, d_cap))
        prediction = predict(plant, gains, target.step_rad)
        meets = (
            prediction.overshoot_pct <= target.overshoot_pct
            and prediction.phase_margin_deg >= target.phase_margin_deg - 1.0
            and prediction.peak_pwm_fraction <= target.pwm_fraction
        )
        result = Suggestion(gains, crossover_hz, prediction, meets)
        if meets or prediction.peak_pwm_fraction > target.pwm_fraction or not target.integral:
            break
    assert result is not None
    return result


def suggest(plant: Plant, target: Target = Target()) -> Suggestion:
    """Gains by the module's rule for `plant` and `target`, checked by `predict`; the
    highest crossover at or below the target's whose clipped registers keep the overshoot
    within the limit and the margin over the floor, found to 2 % (rule 8). Raises
    TuningError for a plant that is not positive and finite."""
    if not all(math.isfinite(x) for x in (plant.g, plant.a, plant.tau_s)):
        raise TuningError(f"plant {plant}: not finite")
    if plant.g <= 0 or plant.a <= 0 or plant.tau_s < 0:
        raise TuningError(f"plant {plant}: g and a must be > 0, tau >= 0")
    wc = 2 * math.pi * target.bandwidth_hz
    # the phase margin floor: 90 deg - wc tau - atan(1 / ratio) >= PM_min
    room = math.radians(90.0 - target.phase_margin_deg) - math.atan(1.0 / INTEGRAL_RATIOS[0])
    if plant.tau_s > 0:
        wc = min(wc, max(room, 0.0) / plant.tau_s)
    failed_hz: float | None = None  # the lowest crossover tried that failed
    result = gains_at(plant, target, wc / (2 * math.pi))
    for _ in range(TRIES - 1):
        if result.meets_target:
            break
        failed_hz = result.crossover_hz
        result = gains_at(plant, target, failed_hz * SHRINK)
    if result.meets_target and failed_hz is not None:  # rule 8: halve the last step
        low, high = result.crossover_hz, failed_hz
        for _ in range(REFINE):
            middle = math.sqrt(low * high)
            trial = gains_at(plant, target, middle)
            if trial.meets_target:
                low, result = middle, trial
            else:
                high = middle
    return result

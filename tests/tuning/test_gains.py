"""The gain rule by its laws: the plant a P-only fit implies gives back the loop it was
fitted from; a higher target gives a higher P; what is offered meets its target and fits
the registers; the prediction of the factory loop is the fitted model's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.tuning.gains import (
    REGISTER_MAX,
    SHRINK,
    TICKS_PER_RAD,
    Plant,
    Target,
    TuningError,
    continuous,
    d_limit,
    gains_at,
    predict,
    registers,
    suggest,
)
from app.tuning.identify import JointModel
from hardware.bus import PositionGains

# the twin's joints as the identification found them (tests/tuning/test_identify.py)
MODEL = JointModel(gain=1.0, wn_rad_s=55.0, zeta=0.75, delay_s=0.008)
PLANT = Plant.of(MODEL)


def test_the_plant_closed_by_the_factory_p_is_the_fitted_loop():
    # Kp0 g / (s^2 + a s + Kp0 g) must be wn^2 / (s^2 + 2 zeta wn s + wn^2)
    kp0, _, _ = continuous(PositionGains())
    assert kp0 * PLANT.g == pytest.approx(MODEL.wn_rad_s**2)
    assert PLANT.a == pytest.approx(2 * MODEL.zeta * MODEL.wn_rad_s)
    # and its predicted bandwidth is the model's (the firmware's 1 ms delay aside)
    seen = predict(Plant(PLANT.g, PLANT.a, 0.0), PositionGains())
    assert seen.bandwidth_hz == pytest.approx(MODEL.bandwidth_hz(), rel=0.02)


def test_registers_and_continuous_gains_are_inverse():
    gains = PositionGains(p=2000, i=1500, d=3000, feedforward_1st=0, feedforward_2nd=0)
    kp, ki, kd = continuous(gains)
    assert kp == pytest.approx(2000 / 128 * TICKS_PER_RAD)  # KpP = P / 128 per tick
    assert registers(kp, ki, kd, 0.0, 0.0) == gains


@pytest.mark.slow
def test_a_higher_target_bandwidth_gives_a_higher_p_and_bandwidth():
    found = [suggest(PLANT, Target(bandwidth_hz=f)) for f in (5.0, 10.0, 20.0, 30.0)]
    p = [s.gains.p for s in found]
    bandwidth = [s.prediction.bandwidth_hz for s in found]
    assert p == sorted(p), p
    assert bandwidth == sorted(bandwidth), bandwidth
    # the predicted bandwidth is near the target where the target was met as asked
    for target, s in zip((5.0, 10.0, 20.0, 30.0), found, strict=True):
        assert s.meets_target
        assert s.crossover_hz <= target * (1 + 1e-9)
        if s.gains.d < d_limit(Target().pwm_fraction):  # D free: the target as asked
            assert s.crossover_hz == pytest.approx(target)
            assert 0.9 * target < s.prediction.bandwidth_hz < 1.5 * target, s


@pytest.mark.slow
@pytest.mark.parametrize("bandwidth_hz", [2.0, 15.0, 40.0, 100.0])
@pytest.mark.parametrize("overshoot_pct", [2.0, 5.0])
def test_what_is_offered_meets_the_target_within_the_registers(bandwidth_hz, overshoot_pct):
    target = Target(bandwidth_hz=bandwidth_hz, overshoot_pct=overshoot_pct)
    s = suggest(PLANT, target)
    assert s.meets_target, s
    # the prediction is of the clipped registers, and it is independent of suggest
    again = predict(PLANT, s.gains, target.step_rad)
    assert again == s.prediction
    assert again.overshoot_pct <= overshoot_pct
    assert again.phase_margin_deg >= target.phase_margin_deg - 1.0
    assert again.peak_pwm_fraction <= target.pwm_fraction
    if bandwidth_hz >= 10.0:  # a slow loop's integral tail outlasts the simulated step
        # within one encoder tick of the goal (the firmware sees whole ticks)
        assert again.static_error_pct < 100.0 / round(target.step_rad * TICKS_PER_RAD)
    values = (s.gains.p, s.gains.i, s.gains.d, s.gains.feedforward_1st, s.gains.feedforward_2nd)
    assert all(isinstance(v, int) and 0 <= v <= REGISTER_MAX for v in values), s.gains


def test_huge_gains_are_clipped_to_the_registers():
    gains = registers(1e9, 1e9, 1e9, 1e9, 1e9)
    assert gains == PositionGains(*(REGISTER_MAX,) * 5)
    assert registers(-1.0, -1.0, -1.0, -1.0, -1.0) == PositionGains(0, 0, 0, 0, 0)


def test_the_step_check_sees_overshoot_and_saturation():
    # P only with no damping from D on a light plant rings: the check must say so
    light = Plant(g=PLANT.g * 10, a=PLANT.a / 10, tau_s=0.001)
    ringing = predict(light, PositionGains(p=3000))
    assert ringing.overshoot_pct > 20.0
    # a 0.3 rad step at P 16383 asks for far more than the PWM limit
    assert predict(PLANT, PositionGains(p=REGISTER_MAX), 0.3).peak_pwm_fraction == 1.0
    # and the integral's absence leaves no static error on this plant (no load) beyond
    # the encoder's tick (13 ticks in 0.02 rad)
    assert predict(PLANT, PositionGains()).static_error_pct < 100.0 / 13


def test_the_feedforward_gains_are_the_models_velocity_and_acceleration_gains():
    s = suggest(PLANT, Target(bandwidth_hz=10.0, feedforward=True))
    # PWM = (y'' + a y') / g: FF1 / 4 per (tick per period) of speed, FF2 / 4 per
    # (tick per period^2) of acceleration
    dt = 0.001
    kv = s.gains.feedforward_1st / 4 * TICKS_PER_RAD * dt
    ka = s.gains.feedforward_2nd / 4 * TICKS_PER_RAD * dt * dt
    assert kv == pytest.approx(PLANT.a / PLANT.g, rel=0.01)
    assert ka == pytest.approx(1 / PLANT.g, rel=0.01)
    off = suggest(PLANT, Target(bandwidth_hz=10.0))  # off by default: the loop's lead is
    assert (off.gains.feedforward_1st, off.gains.feedforward_2nd) == (0, 0)
    assert (off.gains.p, off.gains.i, off.gains.d) == (s.gains.p, s.gains.i, s.gains.d)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("bandwidth_hz", 0.0),
        ("bandwidth_hz", math.nan),
        ("phase_margin_deg", 95.0),
        ("overshoot_pct", -1.0),
        ("pwm_fraction", 2.0),
    ],
)
def test_bad_targets_are_refused_naming_the_field(field, value):
    with pytest.raises(TuningError, match=field):
        Target(**{field: value})


def test_bad_plants_are_refused():
    with pytest.raises(TuningError, match="p_identified"):
        Plant.of(MODEL, p_identified=0)
    with pytest.raises(TuningError):
        suggest(Plant(np.nan, 1.0, 0.001))
    with pytest.raises(TuningError):
        suggest(Plant(1.0, -1.0, 0.001))


@pytest.mark.parametrize("pwm_fraction", [0.5, 0.8, 0.9, 0.95])
def test_the_d_limit_is_the_tick_noise_pwm_bound_by_hand(pwm_fraction):
    # one tick of the error's change per period gives D / 16 PWM (KdP = D / 16); it must
    # fit in the headroom (1 - pwm_fraction) * 885 left above the target's PWM
    limit = d_limit(pwm_fraction)
    assert limit / 16 * 1 <= (1 - pwm_fraction) * 885 + 1e-9
    assert (limit + 1) / 16 * 1 > (1 - pwm_fraction) * 885
    assert d_limit(0.8) == 2832  # 16 * 0.2 * 885 = 2832 exactly


@pytest.mark.slow
@pytest.mark.parametrize("bandwidth_hz", [10.0, 20.0, 30.0, 60.0])
@pytest.mark.parametrize("pwm_fraction", [0.8, 0.9, 0.95])
def test_offered_d_respects_the_tick_noise_bound_and_the_step_stays_honest(
    bandwidth_hz, pwm_fraction
):
    target = Target(bandwidth_hz=bandwidth_hz, pwm_fraction=pwm_fraction)
    s = suggest(PLANT, target)
    assert s.gains.d / 16 <= (1 - pwm_fraction) * 885 + 1e-9
    # a capped D damps less: the rule lowers P instead of offering the overshoot
    assert s.meets_target and s.prediction.overshoot_pct <= target.overshoot_pct
    # the uncapped pole-cancelling D at the same P would have broken the bound
    if s.gains.d == d_limit(pwm_fraction):
        kp, _, _ = continuous(s.gains)
        assert registers(kp, 0.0, kp / PLANT.a, 0.0, 0.0).d > s.gains.d


def test_the_predicted_step_sees_the_capped_d():
    # P for 20 Hz with D capped at 700 rather than the pole-cancelling 4474 rings
    cancelling = suggest(PLANT, Target(bandwidth_hz=20.0, pwm_fraction=0.5))
    kp, ki, _ = continuous(cancelling.gains)
    full = registers(kp, ki, kp / PLANT.a, 0.0, 0.0)
    capped = PositionGains(full.p, full.i, 700, 0, 0)
    assert predict(PLANT, capped).overshoot_pct > predict(PLANT, full).overshoot_pct + 5.0


def test_no_headroom_means_no_d_and_no_integral_means_no_i():
    assert d_limit(1.0) == 0  # no PWM left above the target: no tick noise allowed
    s = suggest(PLANT, Target(bandwidth_hz=20.0, pwm_fraction=1.0, integral=False))
    assert (s.gains.d, s.gains.i) == (0, 0)
    assert s.meets_target and s.gains.p > 0
    # without the pole-cancelling D the damping is a / (2 sqrt(g Kp)): P must stay low
    kp, _, _ = continuous(s.gains)
    assert PLANT.a / (2 * math.sqrt(PLANT.g * kp)) > 0.6


@pytest.mark.parametrize(
    ("pwm_fraction", "overshoot_pct"), [(1.0, 5.0), (1.0, 7.5), (1.0, 10.0), (0.95, 5.0)]
)
def test_a_lowered_crossover_is_found_to_within_a_few_percent_not_fifteen(
    pwm_fraction, overshoot_pct
):
    target = Target(pwm_fraction=pwm_fraction, overshoot_pct=overshoot_pct, integral=False)
    s = suggest(PLANT, target)
    assert s.meets_target and s.crossover_hz < target.bandwidth_hz  # it had to come down
    assert gains_at(PLANT, target, s.crossover_hz) == s
    # the 15 % descent's first passing crossover, and the one above it that failed
    coarse = target.bandwidth_hz
    while not gains_at(PLANT, target, coarse).meets_target:
        coarse *= SHRINK
    # the highest passing crossover on a 1 % grid between them
    grid = [coarse / SHRINK * 0.99**k for k in range(1, 17)]
    best = next(f for f in grid if gains_at(PLANT, target, f).meets_target)
    assert s.crossover_hz >= coarse  # never worse than the 15 % steps
    assert s.crossover_hz >= best / 1.025, (s.crossover_hz, best, coarse)


def test_the_twins_joints_with_no_d_get_the_p_between_the_15_percent_steps():
    # the twin's identified joints (docs/performance.md): with no D and the model's
    # overshoot allowance 7.5 %, the 15 % steps gave P 912 (crossover 6.4 Hz) and the next
    # step up, P 1073, failed; P ~1000 passes on the twin and was missed
    twin = Plant.of(JointModel(gain=1.0, wn_rad_s=53.0, zeta=0.75, delay_s=0.008))
    s = suggest(twin, Target(pwm_fraction=1.0, overshoot_pct=7.5, integral=False))
    assert s.meets_target and 912 < s.gains.p < 1073, s.gains

"""The twin checks by their laws: a gain set whose D turns the encoder's tick into more PWM
than the sinusoid leaves is seen saturating and is not offered; what is offered carries
the verdict a fresh check gives, and passes every limit it claims to. Simulated time only
(the twin's own clock), so the figures do not depend on the machine's load."""

from __future__ import annotations

import pytest

from app.tuning.gains import Plant, Target, d_limit
from app.tuning.identify import JointModel
from app.tuning.twin_check import Limits, check, excess, offer, sinusoid
from hardware.bus import PositionGains

PLANT = Plant.of(JointModel(gain=1.0, wn_rad_s=53.0, zeta=0.75, delay_s=0.008))


@pytest.mark.slow  # seconds of twin per run
def test_a_d_beyond_the_tick_noise_headroom_saturates_and_the_factory_does_not():
    # the pole-cancelling D of the 20 Hz rule, 4474: 280 PWM per tick of the error's change
    loud = sinusoid(PositionGains(p=2845, i=2288, d=4474), seconds=1.0, lead_s=0.02)
    quiet = sinusoid(PositionGains(), seconds=1.0, lead_s=0.02)
    assert loud.at_limit > Limits().at_limit
    assert quiet.at_limit <= Limits().at_limit
    assert d_limit(Target().pwm_fraction) < 4474


@pytest.mark.slow  # a dozen twin runs
def test_what_is_offered_passes_what_it_claims_and_no_saturating_set_is_offered():
    found = offer(PLANT, Target(bandwidth_hz=20.0), seconds=1.0)
    again = check(found.gains, found.verdict.lead_s, 1.0)
    assert again == found.verdict  # simulated time: the same figures every time
    limits = Limits()
    v = found.verdict
    if v.passes:
        assert max(v.plain.at_limit, v.lead.at_limit) <= limits.at_limit
        assert v.overshoot_pct <= limits.overshoot_pct
        assert max(v.rest_m) < limits.rest_m
        assert min(max(v.lead.rmse_m[:2]), max(v.plain.rmse_m[:2])) < limits.rmse_xy_m
    else:  # the best of the tried, and the verdict names what it misses
        assert v.failed
        assert all(len(v.failed) <= len(w.failed) for _, _, w in found.tried)
        ties = [w for _, _, w in found.tried if len(w.failed) == len(v.failed)]
        assert all(excess(v) <= excess(w) for w in ties)
    # a candidate that saturates is never offered while one that does not was tried
    calm = [w for _, _, w in found.tried if "at_limit" not in w.failed]
    if calm:
        assert "at_limit" not in v.failed
    assert found.gains.d <= d_limit(found.target.pwm_fraction)

"""Telemetry pacing is a grid: start + k period, whatever each send costs.

The stream slept one period after each send, so a send taking 10 ms at 50 Hz gave about
33 messages a second. The law, for any send costs: every send time is on the grid; while
sends take less than a period, consecutive ones are exactly one period apart (so N sends
span N periods: the asked rate); when a send overruns, the missed slots are skipped, and
the next send is never in the past.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from app.server.api.telemetry import Pacer, stream_rate_hz


@given(
    st.floats(1.0 / 200.0, 1.0),
    st.floats(0.0, 1e6),
    st.lists(st.floats(0.0, 3.0), min_size=1, max_size=200),
)
@example(0.5295480392976054, 131072.0, [0.0, 1.0])  # a send one period late, to rounding
def test_send_times_are_on_the_period_grid_and_skip_only_what_was_missed(period, start, costs):
    pacer = Pacer(period, start)
    send_s, slot = start, 0
    for cost_periods in costs:
        now = send_s + cost_periods * period  # the send (and the snapshot) took this long
        following = pacer.next(now)
        k = (following - start) / period
        assert math.isclose(k, round(k), abs_tol=1e-6)  # on the grid
        tolerance = 1e-6 * period
        if now <= send_s + period:  # on time: the very next slot
            assert round(k) == slot + 1
        else:  # late: the first slot not yet past
            assert following - period < now + tolerance
        assert following >= now - tolerance  # never in the past
        send_s, slot = following, round(k)


def test_fifty_hertz_with_ten_millisecond_sends_gives_fifty_sends_a_second():
    """The issue's case: 50 asked, sends costing 10 ms each (the old pacing: 33/s)."""
    pacer, now, sends = Pacer(0.02, 0.0), 0.0, 0
    while now < 10.0:
        now += 0.010  # the send
        sends += 1
        now = max(now, pacer.next(now))  # the sleep until the next send
    assert sends == 500


@pytest.mark.parametrize(
    ("asked", "rate"),
    [
        (None, 50.0),
        ("20", 20.0),
        ("0", 1.0),
        ("1e9", 200.0),
        ("inf", 200.0),
        ("-inf", 1.0),
        ("nan", 50.0),
        ("fast", 50.0),
        ("", 50.0),
    ],
)
def test_the_asked_rate_is_clamped_and_nan_is_the_default(asked, rate):
    assert stream_rate_hz(asked, 50.0) == rate

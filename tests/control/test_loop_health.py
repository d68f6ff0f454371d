"""The loop-health light: levels from synthetic 10 s windows, and the gap the recorder keeps."""

from __future__ import annotations

import pytest

from app.control.loop_health import AMBER_FRACTION, THRESHOLDS, classify
from app.control.timing import TimingRecorder, TimingStats
from app.runs import health as run_health


def window(
    hz: float = 200.0, overruns: int = 0, ticks: int = 2000, gap_ms: float = 5.0, p99: float = 0.1
) -> TimingStats:
    """A 10 s window at 200 Hz target with these figures (the rest are irrelevant)."""
    return TimingStats(200.0, hz, 1e3 / hz, 0.02, p99, p99, overruns, ticks, gap_ms)


def test_a_quiet_loop_is_green_with_its_figures():
    light = classify(window(hz=199.9, overruns=1, gap_ms=6.1, p99=0.05))
    assert light.level == "green" and light.reasons == ()
    assert light.rate_share == pytest.approx(199.9 / 200.0)
    assert light.overrun_share == pytest.approx(1 / 2000)
    assert (light.p99_ms, light.longest_gap_ms, light.ticks) == (0.05, 6.1, 2000)


@pytest.mark.parametrize(
    ("figures", "level", "words"),
    [
        # overruns: red over 1 % (20 of 2000), amber over 0.5 % (10 of 2000)
        ({"overruns": 21}, "red", "21 of 2000 ticks overran"),
        ({"overruns": 20}, "amber", "20 of 2000 ticks overran"),
        ({"overruns": 11}, "amber", "11 of 2000"),
        ({"overruns": 10}, "green", None),
        # a gap between ticks: red over 20 ms, amber over 10 ms
        ({"gap_ms": 20.5}, "red", "a 20 ms pause"),
        ({"gap_ms": 19.0}, "amber", "a 19 ms pause"),
        ({"gap_ms": 10.0}, "green", None),
        # the rate: red under 95 % (190 Hz), amber under 97.5 % (195 Hz)
        ({"hz": 189.0}, "red", "189 Hz of 200 Hz"),
        ({"hz": 194.0}, "amber", "194 Hz of 200 Hz"),
        ({"hz": 195.0}, "green", None),
    ],
)
def test_each_limit_turns_the_light(figures, level, words):
    light = classify(window(**figures))
    assert light.level == level
    if words is None:
        assert light.reasons == ()
    else:
        assert len(light.reasons) == 1 and words in light.reasons[0]


def test_red_lists_every_red_limit_and_outranks_amber():
    light = classify(window(hz=150.0, overruns=500, gap_ms=318.0))
    assert light.level == "red" and len(light.reasons) == 3
    assert classify(window(hz=150.0, overruns=15)).reasons == (classify(window(hz=150.0)).reasons)


def test_no_ticks_yet_is_unknown_not_green():
    assert classify(TimingStats(200.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0)).level == "unknown"
    assert classify(window(ticks=1)).level == "unknown"


def test_the_light_and_a_runs_verdict_share_their_limits():
    assert run_health.THRESHOLDS is THRESHOLDS  # one place for the limits
    assert 0 < AMBER_FRACTION < 1
    # the red limit is the run verdict's: a window a run would fail on is red, and back
    assert classify(window(gap_ms=THRESHOLDS.max_gap_ms + 0.1)).level == "red"
    assert classify(window(gap_ms=THRESHOLDS.max_gap_ms)).level == "amber"


def test_the_recorder_keeps_the_longest_gap_between_tick_starts():
    """Starts are deadline + lateness: deadlines 0, 5, 10, 20 ms (a slot skipped), lateness
    0, 1, 0, 3 ms -> starts 0, 6, 10, 23 ms -> gaps 6, 4, 13 ms."""
    recorder = TimingRecorder(rate_hz=200.0)
    for deadline_ms, late_ms in [(0, 0), (5, 1), (10, 0), (20, 3)]:
        recorder.record(deadline_ms * 1e-3, late_ms * 1e-3, 1e-4)
    recorder.refresh()
    assert recorder.last_window().longest_gap_ms == pytest.approx(13.0)
    assert recorder.since_start().longest_gap_ms == pytest.approx(13.0)
    assert classify(recorder.last_window()).level == "red"  # 150 Hz of 200, so red anyway

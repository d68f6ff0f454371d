"""A run's loop health as laws on synthetic tick series: known gaps, overruns and stale
stretches give known figures, and a verdict that flips exactly at each threshold."""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from app.runs.health import THRESHOLDS, assess, assess_series, longest_true_run, summary

HZ = 200.0
PERIOD_MS = 5.0


def series(n: int = 1000, **changes):
    """A perfect 200 Hz run of n ticks: every gap 5 ms, on time, nothing overran or stale."""
    ticks = {
        "gap_ms": np.full(n, PERIOD_MS),
        "lateness_ms": np.full(n, 0.02),
        "overrun": np.zeros(n, dtype=bool),
        "stale": np.zeros(n, dtype=bool),
    }
    for name, (index, value) in changes.items():
        ticks[name][index] = value
    return ticks


def verdict(ticks, simulated: bool = True):
    return assess_series(**ticks, target_hz=HZ, simulated=simulated)


def test_a_perfect_run_is_ok_with_its_figures():
    health = verdict(series())
    assert health["ok"] and health["reasons"] == []
    assert health["rate_hz"] == pytest.approx(HZ)
    assert health["lateness_ms"] == pytest.approx({"p50": 0.02, "p99": 0.02, "worst": 0.02})
    assert (health["overruns"], health["overrun_share"], health["stale_ticks"]) == (0, 0.0, 0)
    assert (health["longest_gap_ms"], health["longest_stale_ms"]) == (PERIOD_MS, 0.0)
    assert health["thresholds"]["max_gap_ms"] == THRESHOLDS.max_gap_ms == 20.0


def test_the_verdict_has_exactly_the_agreed_shape():
    keys = {"ok", "reasons", "rate_hz", "lateness_ms", "overruns", "overrun_share"}
    keys |= {"longest_gap_ms", "stale_ticks", "longest_stale_ms", "thresholds"}
    assert set(verdict(series())) == keys
    assert set(verdict(series())["lateness_ms"]) == {"p50", "p99", "worst"}


@given(st.integers(0, 999), st.floats(0.0, 400.0))
def test_the_longest_gap_is_the_one_put_in_and_flags_over_20_ms(where, gap):
    ticks = series(gap_ms=(where, gap))
    health = verdict(ticks)
    assert health["longest_gap_ms"] == max(gap, PERIOD_MS)
    flagged = any("paused" in r for r in health["reasons"])
    assert flagged == (gap > 20.0)


def test_overruns_flag_above_one_percent_and_not_at_it():
    at_limit = series(overrun=(slice(0, 10), True))  # 10 of 1000 = 1 %: not over
    over = series(overrun=(slice(0, 11), True))
    assert verdict(at_limit)["overruns"] == 10 and verdict(at_limit)["ok"]
    health = verdict(over)
    assert health["overruns"] == 11 and health["overrun_share"] == pytest.approx(0.011)
    assert not health["ok"] and health["reasons"] == ["11 of 1000 ticks overran (1.1%, limit 1%)"]


def test_the_rate_is_ticks_over_time_and_a_slow_loop_is_flagged():
    slow = series(gap_ms=(slice(None), 1e3 / 141))  # the loaded machine's 141 Hz, evenly
    health = verdict(slow)
    assert health["rate_hz"] == pytest.approx(141.0)
    assert any("141 Hz of 200 Hz" in r for r in health["reasons"])
    assert health["longest_gap_ms"] < 20.0  # flagged by its rate alone


def test_a_stale_stretch_lasts_from_the_last_fresh_read_and_is_flagged_over_20_ms():
    four = series(stale=(slice(100, 104), True))  # 4 stale ticks: 20 ms, the limit
    five = series(stale=(slice(100, 105), True))
    assert verdict(four)["longest_stale_ms"] == pytest.approx(20.0)
    assert not any("stale feedback:" in r for r in verdict(four)["reasons"])
    health = verdict(five)
    assert health["stale_ticks"] == 5 and health["longest_stale_ms"] == pytest.approx(25.0)
    assert "stale feedback: the simulator's time did not advance for 25 ms" in health["reasons"][0]
    assert "the reading did not change" in verdict(five, simulated=False)["reasons"][0]


def test_many_short_stale_stretches_are_flagged_by_their_share():
    ticks = series()
    ticks["stale"][::50] = True  # every 50th tick: 20 of 1000, each one tick long
    health = verdict(ticks)
    assert health["longest_stale_ms"] == PERIOD_MS and health["stale_ticks"] == 20
    assert [r for r in health["reasons"] if "20 of 1000 ticks" in r]


@given(st.lists(st.tuples(st.booleans(), st.floats(0.0, 50.0)), max_size=60))
def test_the_longest_true_run_is_the_largest_sum_over_a_stretch(pairs):
    flags = np.array([f for f, _ in pairs], dtype=bool)
    durations = np.array([d for _, d in pairs])
    # by brute force: every stretch of consecutive True flags
    best = 0.0
    for i in range(len(pairs)):
        for j in range(i, len(pairs)):
            if flags[i : j + 1].all():
                best = max(best, float(durations[i : j + 1].sum()))
    assert longest_true_run(flags, durations) == pytest.approx(best)


def test_lateness_percentiles_and_worst_of_a_known_series():
    ticks = series(n=100)
    ticks["lateness_ms"] = np.arange(100, dtype=float)  # 0 .. 99 ms
    health = verdict(ticks)
    assert health["lateness_ms"] == pytest.approx({"p50": 49.5, "p99": 98.01, "worst": 99.0})


def test_rows_from_the_recorder_and_from_the_csv_give_the_same_verdict():
    rows = []
    for k in range(400):
        stale, over = 200 <= k < 210, k % 30 == 0
        rows.append(
            {
                "gap_ms": 37.0 if k == 300 else PERIOD_MS,
                "lateness_ms": 0.1,
                "overrun": over,
                "stale": stale,
                "sim_time_s": 0.005 * min(k, 200),
            }
        )
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    from_csv = list(csv.DictReader(io.StringIO(text.getvalue())))
    assert isinstance(from_csv[0]["overrun"], str)  # "True" / "False": text, as logged
    assert assess(from_csv, HZ) == assess(rows, HZ)
    health = assess(rows, HZ)
    assert health["overruns"] == 14 and health["stale_ticks"] == 10
    assert health["longest_gap_ms"] == 37.0 and health["longest_stale_ms"] == 50.0
    assert len(health["reasons"]) == 4  # overruns, the pause, the stale stretch, stale share


def test_a_log_without_the_health_columns_is_on_time_and_of_unknown_rate():
    health = assess([{"lateness_ms": 0.1}] * 50, HZ)
    assert health["ok"] and health["rate_hz"] == 0.0 and health["longest_gap_ms"] == 0.0


def test_the_summary_line():
    assert summary(verdict(series())) == "loop health: OK"
    bad = verdict(series(10_000, gap_ms=(7, 318.0)))  # long enough to keep its rate
    assert summary(bad) == (
        "loop health: NOT OK — the loop paused 318 ms between two ticks (limit 20 ms)"
    )

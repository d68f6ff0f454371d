"""The touch's logic against a synthetic arm and surface (no simulator): a tip that lags
its command, encoders that quantize it, a force that rises from the surface and reads a
bias while moving; the contact point found, the set force stopped at, the outcomes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.control.state import ContactReading
from app.control.touch import TouchSource, unit_direction

PERIOD_S = 0.005
D = np.array([0.0, 0.0, -1.0])
START = np.array([0.0, 0.0, -0.24])


def _run(surface_m: float, k_n_m: float, lag_m: float, bias_n: float, quantum_m: float, **kw):
    """Drive a touch down onto a surface ``surface_m`` below the start: the measured tip is
    the command less ``lag_m`` while free (on the surface it stops, squeezing the spring of
    stiffness ``k_n_m``), read in steps of ``quantum_m``; the force reads ``bias_n`` more
    along d. Returns the source after it finishes."""
    touch = TouchSource(START, D, 0.01, kw.get("force_n", 2.0), 0.8, kw.get("travel", 0.05))
    for _ in range(20_000):
        setpoint = touch.next(PERIOD_S)
        s = float(np.dot(setpoint.point_m - START, D))
        free = s - lag_m
        pressed = max(0.0, free - surface_m)
        x = min(free, surface_m) + pressed * 0.02  # the tip nearly stops on the surface
        x = round(x / quantum_m) * quantum_m
        # a bias in the reading (friction, unmodelled acceleration), which on the twin
        # stays as the force rises on the surface (docs/contact.md)
        force = k_n_m * pressed + bias_n
        reading = ContactReading(D * force, np.full(3, 0.1), True, None)
        touch.observe_contact(reading, START + D * x, np.zeros(3))
        if setpoint.finished:
            return touch
    raise AssertionError("the touch did not finish")


@pytest.mark.parametrize("k_n_m", [300.0, 600.0, 2000.0])
@pytest.mark.parametrize("lag_m", [0.0, 0.0008, 0.002])
@pytest.mark.parametrize("bias_n", [0.0, 0.45])
def test_the_contact_point_is_where_the_force_starts(k_n_m, lag_m, bias_n) -> None:
    surface = 0.0173
    touch = _run(surface, k_n_m, lag_m, bias_n, quantum_m=0.0002)
    result = touch.touch_result
    assert result.outcome == "contact"
    found = float(np.dot(result.contact_point_m - START, D))
    assert found == pytest.approx(surface, abs=1e-4), (found, surface)
    # stopped at the set force, and the peak is what it stopped at
    assert result.peak_force_n >= 2.0
    assert -result.force_n[2] == pytest.approx(result.peak_force_n)


def test_nothing_within_the_travel_is_no_contact_at_its_end() -> None:
    touch = _run(0.5, 600.0, 0.0, 0.0, 0.0002, travel=0.02)
    result = touch.touch_result
    assert result.outcome == "no contact"
    assert result.travel_m == pytest.approx(0.02)
    assert np.isnan(result.contact_point_m).all()


def test_a_bias_below_the_threshold_is_no_contact() -> None:
    # 0.7 N read in free air, under the 0.8 N threshold: tared away, never "contact"
    touch = _run(0.5, 600.0, 0.0, 0.7, 0.0002, travel=0.02)
    assert touch.touch_result.outcome == "no contact"


@pytest.mark.parametrize(
    ("values", "field"),
    [
        ({"speed_m_s": 0.0}, "speed_m_s"),
        ({"speed_m_s": math.nan}, "speed_m_s"),
        ({"force_n": -1.0}, "force_n"),
        ({"force_n": 0.5}, "force_n"),  # not above the 0.8 N threshold
        ({"max_travel_m": 0.0}, "max_travel_m"),
        ({"retract_m": -0.001}, "retract_m"),
    ],
)
def test_bad_values_are_refused_naming_the_field(values, field) -> None:
    args = {"speed_m_s": 0.01, "force_n": 2.0, "max_travel_m": 0.05, "retract_m": 0.0, **values}
    with pytest.raises(ValueError, match=field):
        TouchSource(START, D, args["speed_m_s"], args["force_n"], 0.8, args["max_travel_m"],
                    args["retract_m"])  # fmt: skip


@pytest.mark.parametrize("direction", [[0, 0, 0], [1, 2], [math.inf, 0, 0], "down"])
def test_a_direction_must_be_three_finite_numbers_not_zero(direction) -> None:
    with pytest.raises(ValueError, match="direction"):
        unit_direction(direction)


def test_an_old_reading_commands_nothing_new() -> None:
    """A lagging simulator's stale read: the touch waits (the command does not advance
    on a force that is not news), then goes on."""
    touch = TouchSource(START, D, 0.01, 2.0, 0.8, 0.05)
    fresh = ContactReading(np.zeros(3), np.full(3, 0.1), True, None)
    for _ in range(50):
        touch.observe_contact(fresh, START, np.zeros(3))
        touch.next(PERIOD_S)
    moved = touch.s
    stale = ContactReading(np.zeros(3), np.full(3, 0.1), True, None, fresh=False)
    for _ in range(50):
        touch.observe_contact(stale, START, np.zeros(3))
        setpoint = touch.next(PERIOD_S)
    assert touch.s == moved
    assert float(np.dot(setpoint.point_m - START, D)) == pytest.approx(moved, abs=1e-15)
    touch.observe_contact(fresh, START, np.zeros(3))
    touch.next(PERIOD_S)
    assert touch.s > moved


def test_a_touch_started_while_the_arm_settles_does_not_see_contact_at_once() -> None:
    """1.1 N read at the start (the arm decelerating from a move), fading over 50 ms: no
    contact before the tare is taken; the surface 10 mm on is found."""
    touch = TouchSource(START, D, 0.01, 2.0, 0.8, 0.05)
    for k in range(10_000):
        setpoint = touch.next(PERIOD_S)
        s = float(np.dot(setpoint.point_m - START, D))
        pressed = max(0.0, s - 0.01)
        force = 1.1 * max(0.0, 1.0 - k * PERIOD_S / 0.05) + 600.0 * pressed
        reading = ContactReading(D * force, np.full(3, 0.1), True, None)
        touch.observe_contact(reading, START + D * min(s, 0.01), np.zeros(3))
        if setpoint.finished:
            break
    result = touch.touch_result
    assert result.outcome == "contact"
    assert float(np.dot(result.contact_point_m - START, D)) == pytest.approx(0.01, abs=1e-4)

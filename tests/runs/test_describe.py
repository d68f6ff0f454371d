"""Runs in words and units (app/runs/describe.py): every kind, no Python reprs."""

from __future__ import annotations

import re

import pytest

from app.runs.describe import describe, loop_figures, number, verdict
from app.runs.report import wrap

REPRS = re.compile(r"True|False|None|nan|inf|\(0\.0|\[|\]|\{|_m\b|_s\b|_hz\b")

KINDS = [
    (
        "chirp",
        {
            "axis": 2,
            "amplitude_m": 0.02,
            "f0_hz": 0.2,
            "f1_hz": 3.0,
            "offset_m": [0.0, 0.0, -0.24],
            "duration_s": 10.0,
            "feedforward": False,
        },
        [
            "chirp on z",
            "amplitude 20 mm",
            "0.2 → 3 Hz over 10 s",
            "(0, 0, −240) mm",
            "feed-forward off",
        ],
    ),
    (
        "step",
        {
            "axis": 0,
            "size_m": -0.005,
            "step_at_s": 0.5,
            "offset_m": [0.0, 0.0, -0.24],
            "duration_s": 2.0,
            "feedforward": False,
        },
        ["step on x", "−5 mm at 0.5 s of 2 s"],
    ),
    (
        "joint-step",
        {
            "servo_id": 2,
            "joint": 2,
            "step_rad": -0.06981317007977318,
            "start_rad": [0.525083, 0.525083, 0.525083],
            "step_at_s": 0.2,
            "duration_s": 1.0,
            "ramp_rad_s": 6.75,
            "phi_rad": 0.0,
        },
        ["step of joint 2 (servo 2): −4° at 0.2 s of 1 s", "joints 30.1 / 30.1 / 30.1°"],
    ),
    (
        "waypoints",
        {
            "points_m": [[0, 0, -0.24], [0.02, 0, -0.24], [0, 0, -0.22]],
            "times_s": [0.0, 1.0, 2.5],
            "feedforward": True,
        },
        ["waypoints: 3 points over 2.5 s", "feed-forward on, lead 20 ms"],
    ),
    (
        "hold",
        {
            "duration_s": 20.0,
            "latency_compensation": True,
            "seed": 7,
            "drift_m": 0.03,
            "tilt_deg": 5.0,
            "yaw_deg": 4.0,
            "gust_m": 0.005,
            "latency_s": 0.04,
            "rate_hz": 50.0,
            "drone": {
                "seed": 7,
                "drift_m": 0.03,
                "tilt_deg": 5.0,
                "yaw_deg": 4.0,
                "gust_m": 0.005,
                "latency_s": 0.04,
                "rate_hz": 50.0,
            },
        },
        [
            "hold in world",
            "20 s",
            "latency compensation on",
            "drift 30 mm",
            "tilt 5°",
            "pose latency 40 ms at 50 Hz",
            "seed 7",
        ],
    ),
    (
        "spiral",  # a kind without its own sentence: its parameters, with units from the names
        {
            "radius_m": 0.03,
            "turns": 4,
            "pitch_rad": 0.5,
            "rate_hz": 2.0,
            "duration_s": 8.0,
            "closed": True,
            "label": "demo",
            "feedforward": False,
        },
        [
            "spiral: radius 30 mm",
            "turns 4",
            "pitch 28.6°",
            "rate 2 Hz",
            "duration 8 s",
            "closed on",
            "label demo",
            "feed-forward off",
        ],
    ),
]


@pytest.mark.parametrize(("kind", "params", "expected"), KINDS, ids=[k[0] for k in KINDS])
def test_every_kind_is_said_in_words_and_units(kind, params, expected):
    text = describe(kind, params, {"feedforward_lead_s": 0.02})
    for piece in expected:
        assert piece in text, (piece, text)
    assert not REPRS.search(text), text


def test_missing_or_odd_values_show_a_dash_not_a_repr():
    text = describe("sinusoid", {"amplitude_m": [None, float("nan"), 0.01], "feedforward": True})
    assert "– / – / 10 mm" in text and "feed-forward on" in text
    assert not REPRS.search(text), text
    health = {"ok": None, "rate_hz": None, "lateness_ms": None}
    assert not REPRS.search(loop_figures({"health": health}) + verdict({"health": health}))


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (0.0, "0"),
        (50.0, "50"),
        (-240.0, "−240"),
        (0.6592, "0.659"),
        (141.23, "141"),
        (1e-7, "0.000"),
        (1.5e5, "150000"),
        (True, "–"),
        (None, "–"),
        (float("inf"), "–"),
    ],
)
def test_numbers_read_as_numbers(value, text):
    assert number(value) == text


def test_wrapped_lines_rejoin_to_the_line_and_fit_the_width():
    line = describe(
        "sinusoid",
        {
            "amplitude_m": [0.05] * 3,
            "frequency_hz": [1.0] * 3,
            "phase_rad": [0.0] * 3,
            "offset_m": [0, 0, -0.24],
            "duration_s": 10.0,
            "feedforward": True,
        },
        {"feedforward_lead_s": 0.02},
    )
    for width in (30, 60, 140):
        pieces = wrap(line, width)
        assert all(len(p) <= width for p in pieces), pieces
        assert " ".join(pieces) == line

"""A run as data (app/link/paths.py): the node's PathSource gives, at each sample, the
setpoints the station's TrajectorySource gives on the planned path."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.link.codec import decode, encode
from app.link.paths import PathSource, SampledPath
from app.runs.source import TrajectorySource
from app.runs.trajectories import SinusoidParams, plan_sinusoid

PERIOD = 0.005


def _plan(lead_s: float = 0.0) -> TrajectorySource:
    params = SinusoidParams(amplitude_m=(0.01, 0.02, 0.0), duration_s=1.0)
    return TrajectorySource(plan_sinusoid(params, np.array([0.0, 0.0, -0.24])), lead_s=lead_s)


@pytest.mark.parametrize("lead_s", [0.0, 0.012])
def test_the_node_plays_the_planned_setpoints_at_every_tick(lead_s: float) -> None:
    planned = _plan(lead_s)
    path = decode(SampledPath, json.loads(encode(planned.sampled(PERIOD))))  # as sent
    played = PathSource(path, "run-1")
    while not planned.finished:
        want, got = planned.next(PERIOD), played.next(PERIOD)
        np.testing.assert_allclose(got.point_m, want.point_m, atol=1e-9)
        np.testing.assert_allclose(got.goal_m, want.goal_m, atol=1e-9)
        assert (got.phase, got.finished) == (want.phase, want.finished)
    assert played.finished


def test_a_late_tick_interpolates_between_samples() -> None:
    path = SampledPath(
        PERIOD, 2 * PERIOD, np.array([[0, 0, 0], [1, 0, 0], [1, 2, 0.0]]), ("timed",), np.zeros(3)
    )
    np.testing.assert_allclose(path.point_at(0.25 * PERIOD), [0.25, 0, 0])
    np.testing.assert_allclose(path.point_at(1.5 * PERIOD), [1, 1, 0])
    np.testing.assert_allclose(path.point_at(99.0), [1, 2, 0])  # clamped at the end


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"points_m": np.array([[0, 0, np.nan], [0, 0, 0.0]])}, "points_m: every point"),
        ({"points_m": np.zeros((1, 3))}, "points_m: expected"),
        ({"phase_index": np.array([0, 3])}, "phase_index: an index names no phase"),
        ({"duration_s": 1.0}, "duration_s: must be in"),
        ({"period_s": -1.0}, "period_s: must be a positive number"),
        ({"lead_s": float("nan")}, "lead_s"),
    ],
)
def test_a_path_that_makes_no_sense_is_refused_naming_the_field(change, words) -> None:
    fields = {
        "period_s": PERIOD,
        "duration_s": PERIOD,
        "points_m": np.zeros((2, 3)),
        "phases": ("timed",),
        "phase_index": np.array([0, 0]),
    }
    with pytest.raises(ValueError, match=words):
        SampledPath(**{**fields, **change})

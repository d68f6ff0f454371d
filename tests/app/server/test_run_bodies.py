"""Every run body the API accepts plans to a run or to GoalRejected, never another error
(the trajectory generator's failures were 500s); and the bodies that cannot run are
refused by the request model, naming the field."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from app.control.errors import GoalRejected
from app.server.api.runs import ChirpRequest, SinusoidRequest, StepRequest, WaypointsRequest
from tests.support.planning import resting_manager

# numbers near and beyond the models' bounds, and the awkward ones in between
NUMBERS = st.one_of(
    st.floats(-0.3, 0.3),
    st.floats(-25.0, 25.0),
    st.sampled_from([0.0, 1e-9, -1e-9, 1e-6, 0.999, 1.0, 1.001, 1e308, -1e308, 5e-324]),
)
SHORT_S = st.one_of(st.floats(1e-6, 3.0), st.sampled_from([1e-9, 0.005, 600.0, 600.1]))
VECTOR = st.lists(NUMBERS, min_size=3, max_size=3)


def bodies(model, **fields):
    """Dicts with any subset of ``fields`` (the rest default)."""
    return st.fixed_dictionaries({}, optional=fields).map(lambda d: (model, d))


WAYPOINTS = (
    st.integers(2, 6)
    .flatmap(
        lambda n: st.fixed_dictionaries(
            {
                "points_m": st.lists(
                    st.one_of(VECTOR, st.just([0.0, 0.0, -0.24]), st.just([0.05, 0.0, -0.24])),
                    min_size=n,
                    max_size=n,
                ),
                "times_s": st.lists(st.floats(1e-7, 2.0), min_size=n - 1, max_size=n - 1).map(
                    lambda gaps: [0.0, *(sum(gaps[: i + 1]) for i in range(len(gaps)))]
                ),
            }
        )
    )
    .map(lambda d: (WaypointsRequest, d))
)

RUN_BODIES = st.one_of(
    bodies(
        SinusoidRequest,
        amplitude_m=VECTOR,
        frequency_hz=st.lists(st.floats(0.0, 21.0), min_size=3, max_size=3),
        phase_rad=VECTOR,
        offset_m=VECTOR,
        duration_s=SHORT_S,
    ),
    bodies(
        ChirpRequest,
        axis=st.integers(0, 2),
        amplitude_m=NUMBERS,
        f0_hz=st.floats(0.0, 21.0),
        f1_hz=st.floats(0.0, 21.0),
        offset_m=VECTOR,
        duration_s=SHORT_S,
    ),
    bodies(
        StepRequest,
        axis=st.integers(0, 2),
        size_m=NUMBERS,
        step_at_s=st.floats(0.0, 3.0),
        offset_m=VECTOR,
        duration_s=SHORT_S,
    ),
    WAYPOINTS,
)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    return resting_manager(tmp_path_factory.mktemp("runs"))


@pytest.mark.slow  # hypothesis over planned runs
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(RUN_BODIES)
def test_an_accepted_run_body_plans_or_is_rejected_never_errs(runs, case):
    model, data = case
    try:
        body = model.model_validate(data)
    except ValidationError:
        event("refused by the model")
        return  # a 422 naming the field: the model's job, tested below
    try:
        runs.plan(body.params())
        event(f"{model.__name__} planned")
    except GoalRejected as exc:
        event(f"{model.__name__} rejected")
        assert str(exc)  # says why


@pytest.mark.parametrize(
    ("model", "data", "field"),
    [
        (SinusoidRequest, {"amplitude_m": [1e308, 0, 0]}, "amplitude_m.0"),
        (SinusoidRequest, {"offset_m": [0, 0, -1e300]}, "offset_m.2"),
        (SinusoidRequest, {"duration_s": "2"}, "duration_s"),
        (ChirpRequest, {"f0_hz": 20.0, "f1_hz": 0.0}, "f1_hz"),
        (ChirpRequest, {"axis": "2"}, "axis"),
        (StepRequest, {"step_at_s": 2.0, "duration_s": 2.0}, "step_at_s"),
        (StepRequest, {"step_at_s": 5.0, "duration_s": 2.0}, "step_at_s"),
        (WaypointsRequest, {"points_m": [[0, 0, -0.24]] * 2, "times_s": [0, 1, 2]}, "times_s"),
        (WaypointsRequest, {"points_m": [["0", "0", "-0.24"]] * 2, "times_s": [0, 1]}, "points_m"),
    ],
)
def test_a_body_that_cannot_run_is_refused_naming_the_field(model, data, field):
    with pytest.raises(ValidationError) as caught:
        model.model_validate(data)
    assert field in str(caught.value)


def test_waypoints_too_fast_for_their_distance_are_a_goal_rejected(tmp_path):
    """5 cm in a microsecond, from within 1 mm of the start: a ruckig error before."""
    runs = resting_manager(tmp_path, [0.0, 0.0, -0.2405])
    body = WaypointsRequest(points_m=[[0, 0, -0.24], [0.05, 0, -0.24]], times_s=[0, 1e-6])
    with pytest.raises(GoalRejected, match="too fast|joint speed"):
        runs.plan(body.params())

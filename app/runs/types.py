"""The test run types the API starts, from one registry (``RUN_TYPES``).

A run type is its parameters, its path and its sentence:

- the parameters: one pydantic request model, the body of ``POST /api/tests/<name>``,
  with each field's bounds and description written once, here;
- the path: the frozen dataclass the model's ``params()`` builds (``TimedPath``: what the
  run manager plans and the loop follows). Its defaults are the model's defaults: written
  once, in the dataclass (app/runs/paths.py, app/runs/trajectories.py), which the command
  line imports without pydantic (``deltadash --help`` stays fast), and read from it here;
- the sentence: how app/runs/describe.py says a run of it in words and units.

The routes (app/server/api/runs.py) are made from the registry: a new run type is an
entry here, its path and its sentence.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from itertools import pairwise
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, model_validator

from app.control.errors import GoalRejected
from app.fields import ReachVector3, Vector3
from app.runs.describe import SENTENCES
from app.runs.paths import ChirpParams, StepParams, WaypointParams
from app.runs.trajectories import SinusoidParams, TimedPath

MAX_WAYPOINTS = 1000

Seconds = Annotated[float, Field(gt=0, le=600, allow_inf_nan=False, strict=True)]
Axis = Annotated[int, Field(ge=0, le=2, strict=True, description="0 = x, 1 = y, 2 = z")]

HzOrZero = Annotated[float, Field(ge=0, le=20, allow_inf_nan=False, strict=True)]
Hz = Annotated[float, Field(gt=0, le=20, allow_inf_nan=False, strict=True)]

# the paths' defaults, the models' defaults (a path's tuples are the body's JSON lists)
_SINE, _CHIRP, _STEP = SinusoidParams(), ChirpParams(), StepParams()
_WAYPOINTS = {f.name: f.default for f in fields(WaypointParams)}  # points and times: none
# an example the schema gives (the page's first rows): a 30 mm square at the sinusoid's
# centre, a second a side, back where it began
_SQUARE_M = (
    (0.0, 0.0, -0.24),
    (0.03, 0.0, -0.24),
    (0.03, 0.03, -0.24),
    (0.0, 0.03, -0.24),
    (0.0, 0.0, -0.24),
)
_SQUARE_S = (0.0, 1.0, 2.0, 3.0, 4.0)


class RunRequest(BaseModel):
    """A run type's parameters: a strict JSON body (no unknown fields, numbers are numbers)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    def params(self) -> TimedPath:
        """The path these parameters give (SI units, base frame). Abstract: every request
        model of the registry defines it (tests/runs/test_run_types.py builds each)."""
        raise NotImplementedError(f"{type(self).__name__} is not a registered run type")


def _triple(values: list[float]) -> tuple[float, float, float]:
    x, y, z = values
    return x, y, z


class SinusoidRequest(RunRequest):
    """Per-axis sinusoid; every field optional, defaults are the thesis test (ch. 6.1)."""

    amplitude_m: ReachVector3 = list(_SINE.amplitude_m)
    frequency_hz: Annotated[list[HzOrZero], Field(min_length=3, max_length=3)] = list(
        _SINE.frequency_hz
    )
    phase_rad: Vector3 = list(_SINE.phase_rad)
    offset_m: ReachVector3 = list(_SINE.offset_m)
    duration_s: Seconds = _SINE.duration_s
    feedforward: bool = _SINE.feedforward
    phi_amplitude_rad: Annotated[float, Field(ge=0, le=math.pi, allow_inf_nan=False)] = Field(
        _SINE.phi_amplitude_rad,
        description="with a [wrist]: phi(t) = A sin(2 pi f t) [rad]; 0 leaves it alone",
    )
    phi_frequency_hz: HzOrZero = Field(
        _SINE.phi_frequency_hz, description="the wrist's frequency f [Hz]"
    )

    def params(self) -> SinusoidParams:
        """The sinusoid (tuples of the body's lists)."""
        return SinusoidParams(
            _triple(self.amplitude_m),
            _triple(self.frequency_hz),
            _triple(self.phase_rad),
            _triple(self.offset_m),
            self.duration_s,
            self.feedforward,
            self.phi_amplitude_rad,
            self.phi_frequency_hz,
        )


class ChirpRequest(RunRequest):
    """Linear frequency sweep on one axis, for identifying the servo response."""

    axis: Axis = _CHIRP.axis
    amplitude_m: Annotated[float, Field(gt=0, le=0.2, allow_inf_nan=False, strict=True)] = (
        _CHIRP.amplitude_m
    )
    f0_hz: Hz = _CHIRP.f0_hz
    f1_hz: Hz = _CHIRP.f1_hz
    offset_m: ReachVector3 = list(_CHIRP.offset_m)
    duration_s: Seconds = _CHIRP.duration_s
    feedforward: bool = _CHIRP.feedforward

    def params(self) -> ChirpParams:
        """The chirp (the offset a tuple)."""
        return ChirpParams(**{**self.model_dump(), "offset_m": _triple(self.offset_m)})


class StepRequest(RunRequest):
    """A position step on one axis (servo step response), within the run."""

    axis: Axis = _STEP.axis
    size_m: Annotated[float, Field(ge=-0.05, le=0.05, allow_inf_nan=False, strict=True)] = (
        _STEP.size_m
    )
    step_at_s: Annotated[float, Field(ge=0, le=60, allow_inf_nan=False, strict=True)] = (
        _STEP.step_at_s
    )
    offset_m: ReachVector3 = list(_STEP.offset_m)
    duration_s: Seconds = _STEP.duration_s
    phi_step_rad: Annotated[float, Field(ge=-math.pi, le=math.pi, allow_inf_nan=False)] = Field(
        _STEP.phi_step_rad,
        description="with a [wrist]: a step of phi [rad] at step_at_s too; 0 leaves it alone",
    )

    @model_validator(mode="after")
    def _step_inside(self) -> StepRequest:
        if self.step_at_s >= self.duration_s:
            raise ValueError(
                f"step_at_s: {self.step_at_s:g} s is not before the run's end "
                f"(duration_s = {self.duration_s:g} s)"
            )
        return self

    def params(self) -> StepParams:
        """The step (the offset a tuple; no feed-forward: the body has none)."""
        return StepParams(**{**self.model_dump(), "offset_m": _triple(self.offset_m)})


class WaypointsRequest(RunRequest):
    """Points [m] reached at times [s] (first at 0), resting at each; minimum-jerk between."""

    points_m: Annotated[
        list[ReachVector3],
        Field(min_length=2, max_length=MAX_WAYPOINTS, examples=[[list(p) for p in _SQUARE_M]]),
    ]
    times_s: Annotated[
        list[Annotated[float, Field(ge=0, le=600, allow_inf_nan=False, strict=True)]],
        Field(min_length=2, max_length=MAX_WAYPOINTS, examples=[list(_SQUARE_S)]),
    ]
    feedforward: bool = _WAYPOINTS["feedforward"]

    @model_validator(mode="after")
    def _timed(self) -> WaypointsRequest:
        if len(self.times_s) != len(self.points_m):
            raise ValueError(
                f"times_s: one time per point ({len(self.times_s)} times, "
                f"{len(self.points_m)} points)"
            )
        if self.times_s[0] != 0.0 or not all(b > a for a, b in pairwise(self.times_s)):
            raise ValueError("times_s: must start at 0 and increase")
        return self

    def params(self) -> WaypointParams:
        """The waypoints; GoalRejected for what the path refuses and the schema cannot say."""
        points = tuple(_triple(p) for p in self.points_m)
        try:
            return WaypointParams(points, tuple(self.times_s), self.feedforward)
        except ValueError as exc:  # counts and order the schema cannot say
            raise GoalRejected(str(exc)) from exc


@dataclass(frozen=True)
class RunType:
    """One kind of test run: ``name`` (the run's kind in run.json, the route
    ``POST /api/tests/<name>``), ``request`` (its parameters: the body, bounds and
    defaults), ``path`` (the dataclass ``request.params()`` builds), ``sentence`` (the run
    in words, from its saved params dict) and ``doc`` (what the route's documentation
    says of it)."""

    name: str
    request: type[RunRequest]
    path: type
    sentence: Callable[[dict[str, Any]], str]
    doc: str

    def build(self, body: dict[str, Any]) -> TimedPath:
        """The path of a JSON ``body`` (a dict; missing fields default). Raises pydantic's
        ValidationError for a body the model refuses, GoalRejected for a path that cannot
        be made of it."""
        return self.request.model_validate(body).params()


def _entry(name: str, request: type[RunRequest], path: type, doc: str) -> RunType:
    return RunType(name, request, path, SENTENCES[name], doc)


RUN_TYPES: dict[str, RunType] = {
    t.name: t
    for t in (
        _entry(
            "sinusoid",
            SinusoidRequest,
            SinusoidParams,
            "Check the whole path, then run it; 422 names the first infeasible time and point.",
        ),
        _entry(
            "chirp",
            ChirpRequest,
            ChirpParams,
            "A frequency sweep f0 -> f1 on one axis; checked like the sinusoid.",
        ),
        _entry(
            "step",
            StepRequest,
            StepParams,
            "A step on one axis; small steps pass the joint-speed limit unchanged.",
        ),
        _entry(
            "waypoints",
            WaypointsRequest,
            WaypointParams,
            "Timed waypoints (pick-and-place, raster); checked like the sinusoid.",
        ),
    )
}
"""The run types by name, in the order the API lists their routes."""

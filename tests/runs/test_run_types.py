"""The run types come from one registry (app/runs/types.py): each type's defaults build a
path that plans, every start route's body is the registry's model, and the defaults are
written once (the path dataclass's; the model, the OpenAPI document and GET /api/tests,
which the page's form is made from, agree with it)."""

from __future__ import annotations

import dataclasses
from html.parser import HTMLParser
from pathlib import Path

import pytest

from app.runs.describe import SENTENCES, describe
from app.runs.trajectories import SinusoidParams
from app.runs.types import RUN_TYPES, SinusoidRequest
from app.server.api import runs as runs_api
from tests.support.planning import resting_manager

PAGE = Path(__file__).resolve().parents[2] / "static" / "index.html"
# the fields without a default, given where a type has them
REQUIRED = {
    "waypoints": {
        "points_m": [[0.0, 0.0, -0.24], [0.02, 0.0, -0.24], [0.02, 0.02, -0.22]],
        "times_s": [0.0, 0.5, 1.0],
    }
}
TYPES = list(RUN_TYPES.values())
IDS = list(RUN_TYPES)


def test_the_registry_names_the_routes_run_types():
    assert IDS == ["sinusoid", "chirp", "step", "waypoints"]
    assert all(name == t.name for name, t in RUN_TYPES.items())


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    return resting_manager(tmp_path_factory.mktemp("runs"))


@pytest.mark.parametrize("run_type", TYPES, ids=IDS)
def test_a_run_types_defaults_build_a_path_that_plans(run_type, runs):
    path = run_type.build(REQUIRED.get(run_type.name, {}))
    assert isinstance(path, run_type.path)
    plan, _ = runs.plan(path)
    assert plan.duration_s >= path.duration_s > 0  # approach + timed part + stop


@pytest.mark.parametrize("run_type", TYPES, ids=IDS)
def test_a_run_types_defaults_are_its_paths(run_type):
    """The dataclass's defaults are the model's: ``ChirpParams()`` is the default body's."""
    if run_type.name not in REQUIRED:
        assert run_type.path() == run_type.request().params()
    for field in dataclasses.fields(run_type.path):
        if field.name in run_type.request.model_fields and field.default is not dataclasses.MISSING:
            default = run_type.request.model_fields[field.name].default
            as_path = tuple(default) if isinstance(default, list) else default
            assert as_path == field.default, field.name


@pytest.mark.parametrize("run_type", TYPES, ids=IDS)
def test_a_run_types_sentence_is_describes(run_type):
    params = dataclasses.asdict(run_type.build(REQUIRED.get(run_type.name, {})))
    assert run_type.sentence is SENTENCES[run_type.name]
    assert describe(run_type.name, params).startswith(run_type.sentence(params))


def routes():
    return {route.path: route for route in runs_api.router.routes if hasattr(route, "body_field")}


def test_every_start_route_takes_its_registry_model():
    starts = {path: r for path, r in routes().items() if path.startswith("/tests/")}
    assert set(starts) == {f"/tests/{name}" for name in RUN_TYPES}
    for run_type in TYPES:
        route = starts[f"/tests/{run_type.name}"]
        assert route.methods == {"POST"}
        assert route.name == f"start_{run_type.name}"
        assert route.body_field.field_info.annotation is run_type.request
        assert route.description == run_type.doc


def test_the_bodies_stay_importable_from_the_runs_router():
    for run_type in TYPES:
        assert getattr(runs_api, run_type.request.__name__) is run_type.request


@pytest.mark.slow
def test_the_openapi_document_has_each_models_defaults():
    from app.config import load_settings
    from app.server import create_app

    document = create_app(load_settings()).openapi()
    schemas = document["components"]["schemas"]
    for run_type in TYPES:
        operation = document["paths"][f"/api/tests/{run_type.name}"]["post"]
        ref = operation["requestBody"]["content"]["application/json"]["schema"]["$ref"]
        assert ref.endswith(f"/{run_type.request.__name__}")
        properties = schemas[run_type.request.__name__]["properties"]
        for name, field in run_type.request.model_fields.items():
            if not field.is_required():
                assert properties[name]["default"] == field.default, name


class _FormValues(HTMLParser):
    """The ``value`` of each input inside ``<form id=...>`` (a checkbox: whether checked)."""

    def __init__(self, form_id: str) -> None:
        super().__init__()
        self.form_id, self.inside, self.values = form_id, False, {}

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "form":
            self.inside = attrs.get("id") == self.form_id
        elif tag == "input" and self.inside and "name" in attrs:
            checkbox = attrs.get("type") == "checkbox"
            self.values[attrs["name"]] = "checked" in attrs if checkbox else attrs["value"]

    def handle_endtag(self, tag):
        if tag == "form":
            self.inside = False


def test_the_pages_run_form_repeats_no_default():
    """The page's test-run form is made from GET /api/tests (the models' schemas, their
    defaults: tests/app/server/test_api_run_types.py), so index.html holds no field of its
    own to drift from the models'."""
    parser = _FormValues("run-form")
    parser.feed(PAGE.read_text(encoding="utf-8"))
    assert parser.values == {}
    assert "run-fields" in PAGE.read_text(encoding="utf-8")
    assert SinusoidParams() == SinusoidRequest().params()


def test_waypoints_without_their_points_are_refused():
    with pytest.raises(ValueError, match="points_m"):
        RUN_TYPES["waypoints"].build({})

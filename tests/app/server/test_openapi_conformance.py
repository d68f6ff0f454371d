"""The OpenAPI document and the answers agree (schemathesis): for every operation of
/openapi.json, generated requests (bodies, queries and path parameters that fit the
schema, and ones that do not; EXAMPLES per operation and mode, derandomized) are sent to
the app in-process on the emulated bus, and each answer must be no 5xx but the documented
503 (a loaded machine may see the loop or a worker not answer in time), have a status
code the operation documents, and a body that fits that status code's schema. About a
minute on two shared cores.

The app drives a simulated robot; the test holds the control lease, so motion routes
run (runs, calibrations and tunings start; a later one is a 409). No route ends the
server (there is no shutdown route); none is excluded. The calls go through the
project's own test client (``Host: 127.0.0.1``: app/server/origins.py refuses
``testserver``), so the app's lifespan is the client's, not schemathesis's.
"""

from __future__ import annotations

import re
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable

from tests.support.app_client import make_client
from tests.support.lease import take_lease

pytestmark = pytest.mark.slow
# 503 is the documented "not now" (the loop, a worker or a plan did not answer in time,
# which a loaded machine may see: Retry-After); any other 5xx is a bug
NOT_NOW = 503
EXAMPLES = 10  # per operation and mode: about 48 operations x 2 modes, well under 90 s
EXCLUDED: set[tuple[str, str]] = set()  # (method, path): none ends the server


@pytest.fixture(scope="module")
def schemathesis():
    """schemathesis, imported here (not at collection: every test process would pay for it,
    and pyproject.toml keeps its pytest plugin off, which this module does not use)."""
    return pytest.importorskip("schemathesis")


def checks() -> list[Any]:
    from schemathesis.specs.openapi.checks import (
        response_schema_conformance,
        status_code_conformance,
    )

    return [status_code_conformance, response_schema_conformance]


@pytest.fixture(scope="module")
def app_client(tmp_path_factory):
    with make_client(tmp_path_factory.mktemp("runs")) as client:
        take_lease(client)
        yield client


def operations(schemathesis, client) -> list[Any]:
    schema = schemathesis.openapi.from_dict(client.get("/openapi.json").json())
    found = [result.ok() for result in schema.get_all_operations()]
    return [op for op in found if (op.method.upper(), op.path) not in EXCLUDED]


def send(client, case) -> Any:
    """The case through the test client (requests-style kwargs to httpx's)."""
    kwargs = case.as_transport_kwargs(base_url="http://127.0.0.1")
    kwargs.pop("cookies", None)
    if "data" in kwargs:
        kwargs["content"] = kwargs.pop("data")
    headers = dict(kwargs.pop("headers") or {})
    headers.update(client.headers)  # the lease's token, if any
    return client.request(kwargs.pop("method"), kwargs.pop("url"), headers=headers, **kwargs)


@pytest.mark.parametrize("mode", ["positive", "negative"])
def test_answers_agree_with_the_openapi_document(schemathesis, app_client, mode):
    tested = []
    for operation in operations(schemathesis, app_client):
        strategy = operation.as_strategy(generation_mode=schemathesis.GenerationMode(mode))

        @settings(
            max_examples=EXAMPLES,
            deadline=None,
            database=None,
            derandomize=True,  # the same cases each run: a failure is a mismatch, not luck
            suppress_health_check=list(HealthCheck),
        )
        @given(case=strategy)
        def call(case):
            response = send(app_client, case)
            status = response.status_code
            assert status < 500 or status == NOT_NOW, (case.method, case.path, response.text)
            case.validate_response(response, checks=checks())

        try:
            call()
            tested.append(f"{operation.method.upper()} {operation.path}")
        except Unsatisfiable:  # negative: nothing to break (no parameters, no body)
            pass
        app_client.post("/api/reset")
    assert len(tested) > (40 if mode == "positive" else 20), tested


def test_every_json_body_refused_as_invalid_fits_its_422_schema(schemathesis, app_client):
    """A JSON array where each body is an object: FastAPI's own validation error, which
    random cases may miss, checked against each route's documented 422."""
    take_lease(app_client)  # the generated cases before may have given control back
    bodies = [op for op in operations(schemathesis, app_client) if op.body]
    assert len(bodies) >= 20
    for operation in bodies:
        names = re.findall(r"{(\w+)}", operation.path)  # servo 1, run or file "1"
        case = operation.Case(
            body=[], media_type="application/json", path_parameters=dict.fromkeys(names, "1")
        )
        response = send(app_client, case)
        assert response.status_code == 422, (operation.path, response.text)
        case.validate_response(response, checks=checks())

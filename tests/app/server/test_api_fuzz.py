"""Property-based API test: generated bodies for every POST route of /openapi.json.

On the simulator with torque on and the arm settled, whatever is sent: never a 5xx, and a
refused request (4xx) leaves the commanded point where it was. After an accepted request
that moved anything, the arm is brought back to rest before the next example. The number of
examples is bounded (make test runs it; it is marked slow, out of the inner loop).
"""

from __future__ import annotations

import json
import os
from urllib.parse import quote

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.openapi import JUNK, bodies
from tests.support.wait import ok_json, wait_for

REST_M = [0.0, 0.0, -0.24]
# bounded for the fast suite; DELTADASH_FUZZ_EXAMPLES=3000 for a long search
EXAMPLES = int(os.environ.get("DELTADASH_FUZZ_EXAMPLES", "200"))


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    runs = {"max_samples": 4000}
    with make_client(tmp_path_factory.mktemp("fuzz"), backend="sim", runs=runs) as client:
        to_rest(client)
        yield client


def post_routes(client) -> list[tuple[str, dict | None]]:
    doc = client.get("/openapi.json").json()
    routes = []
    for path, operations in doc["paths"].items():
        if "post" in operations:
            content = operations["post"].get("requestBody", {}).get("content", {})
            schema = content.get("application/json", {}).get("schema")
            routes.append((path, None if schema is None else (doc, schema)))
    return routes


def snapshot(client):
    """The loop's latest state, read directly (as /api/status serialises it; cheaper)."""
    return client.app.state.controller.snapshot()


def commanded(client) -> np.ndarray:
    return np.array(snapshot(client).point_commanded_m, dtype=float)


def procedure_active(client) -> bool:
    """A run, a calibration or a tuning accepted earlier: its thread may move the arm later
    (a procedure plans first, then moves; CI's loaded run saw one move it 4 mm after the
    arm had looked still)."""
    state = client.app.state
    return bool(state.runs.busy() or state.calibration.running() or state.tuning.running())


STILL_TICKS = 10  # the setpoint must not move at all over this many ticks (50 ms)


def at_rest(client) -> bool:
    """Torque on, no e-stop or fault, no run or procedure going, idle or holding a goal,
    commanded at REST_M, still: not by a nanometre over STILL_TICKS ticks (a held jog just
    accepted starts jerk-limited, a few micrometres in its first ticks, then runs on until
    its heartbeat lapses: a looser, shorter look once took it for rest, and the next,
    refused, example saw the arm 4 mm away)."""
    if procedure_active(client):
        return False
    now = ok_json(client.get("/api/status"))
    if not now["torque"] or now["estopped"] or now["faults"] or now["mode"] not in ("idle", "jog"):
        return False
    first, tick = commanded(client), snapshot(client).tick
    wait_for(lambda: snapshot(client).tick > tick + STILL_TICKS, "loop ticks")
    still = np.allclose(first, commanded(client), rtol=0, atol=1e-9)
    return still and np.allclose(first, REST_M, rtol=0, atol=1e-6)


def to_rest(client, procedures: tuple[str, ...] = ()) -> None:
    """Back to the standard state: control taken, the ``procedures`` a generated request
    started (``/api/tuning/<id>``, ...) aborted (a tuning's twin check may compute for
    minutes after an e-stop), e-stop cleared, torque on, the goal at REST_M and the
    setpoint still there. Each step is retried: on a loaded machine the loop may answer a
    command late (503) just after an e-stop stopped a run."""
    take_lease(client, "fuzz")  # again: a generated request may have taken it over
    for procedure in procedures:
        client.post(f"{procedure}/abort")  # 409 once it has ended: nothing to abort
    steps = [
        ("/api/estop", None),
        ("/api/reset", None),
        ("/api/torque", {"enabled": True}),
        ("/api/goal", {"position_m": REST_M}),
    ]
    for path, body in steps:
        answers = []

        def accepted(path=path, body=body, answers=answers) -> bool:
            answers.append(client.post(path, json=body))
            return answers[-1].status_code == 200

        wait_for(accepted, f"POST {path} accepted", seen=lambda answers=answers: answers[-1].text)
    wait_for(lambda: at_rest(client), "the arm at rest at the start point", timeout_s=60)


@st.composite
def requests(draw, routes):
    path, schema = draw(st.sampled_from(routes))
    if "{run_id}" in path:
        run_id = draw(st.text(st.characters(codec="ascii", exclude_characters="/"), max_size=12))
        path = path.replace("{run_id}", quote(run_id, safe="") or "x")
    body = draw(JUNK if schema is None else st.one_of(bodies(*schema), bodies(*schema), JUNK))
    return path, json.dumps(body, allow_nan=True)


@pytest.mark.slow  # ~20 s for 200 examples: in make test, not in the inner loop
def test_no_generated_body_gives_a_5xx_or_moves_the_robot_when_refused(sim):
    routes = post_routes(sim)
    assert len(routes) >= 15  # every POST route of the API is in the draw
    history: list[tuple] = []

    @settings(
        max_examples=EXAMPLES,
        deadline=None,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
    @given(requests(routes))
    def check(request):
        path, content = request
        before = commanded(sim)
        response = sim.post(path, content=content, headers={"content-type": "application/json"})
        # what came just before, for a failure's message (a move may be an earlier one's)
        history.append((path, content[:300], response.status_code, response.text[:300]))
        del history[:-4]
        assert response.status_code < 500, (path, content, response.text, history)
        event(f"{response.status_code} {path}")
        if response.status_code >= 400:
            after = commanded(sim)
            mode = snapshot(sim).mode
            assert np.allclose(before, after, rtol=0, atol=1e-9), (after - before, mode, history)
        elif not at_rest(sim):
            event("brought back to rest")
            run_id = response.json().get("run_id") if path.endswith("/run") else None
            to_rest(sim, (f"{path.removesuffix('/run')}/{run_id}",) if run_id else ())

    check()

"""One authority for motion over HTTP: the secret lease, the token on reads beyond
loopback, Bearer only, e-stop open to anyone (issue 14, points 4, 9 and 10)."""

from __future__ import annotations

import functools
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import load_settings
from app.server import create_app
from app.server.backends import open_backend
from tests.support.app_client import LocalClient, unmoved
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

TOKEN = "authority-test-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
GOAL = [0.01, -0.01, -0.23]
# every route that can move the robot or change its power, with a body it would accept
COMMANDS = [
    ("/api/goal", {"position_m": GOAL}),
    ("/api/jog", {"delta_m": [0.0, 0.0, 0.005]}),
    ("/api/move", {"position_m": GOAL}),
    ("/api/torque", {"enabled": False}),
    ("/api/reset", None),
    ("/api/hold", {"frame": "current", "source": "simulated"}),
    ("/api/tests/hold", {"duration_s": 1.0}),
    ("/api/tests/sinusoid", {"duration_s": 1.0}),
    ("/api/tests/chirp", {"duration_s": 1.0}),
    ("/api/tests/step", {"duration_s": 1.0}),
    ("/api/tests/waypoints", {"points_m": [GOAL, GOAL], "times_s": [0.0, 1.0]}),
    ("/api/runs/nope/abort", None),
    ("/api/programs/run", {"gcode": "G4 P0.5"}),
]
# POST routes that need no lease: stopping, taking or giving back the lease, pose input
# (it feeds a hold the lease holder started; it cannot start one), the run types' previews and
# a program's check and dry run (they move nothing: the dry run plays on a twin of its own)
NO_LEASE = {
    "/api/estop",
    "/api/lease",
    "/api/mav/pose",
    "/api/tests/sinusoid/check",
    "/api/tests/chirp/check",
    "/api/tests/step/check",
    "/api/tests/waypoints/check",
    "/api/programs/check",
    "/api/programs/dry-run",
}


def _app(tmp_path_factory, **server) -> TestClient:
    folder = tmp_path_factory.mktemp("runs")
    settings = load_settings(
        hardware={"backend": "emulated"},
        runs={"folder": str(folder)},
        link={"robot": "in-process"},
        server={"viser_port": 0, "token": TOKEN, **server},
    )
    opener = functools.partial(open_backend, emulator_in_process=True)
    return LocalClient(create_app(settings, backend_opener=opener))


@pytest.fixture(scope="module")
def networked(tmp_path_factory) -> Iterator[TestClient]:
    """Reachable from other machines (0.0.0.0), with a token."""
    with _app(tmp_path_factory, host="0.0.0.0") as client:
        yield client


@pytest.fixture(scope="module")
def local(tmp_path_factory) -> Iterator[TestClient]:
    """Loopback only, with a token: reads are open, commands need the token and lease."""
    with _app(tmp_path_factory, host="127.0.0.1") as client:
        yield client


def robot(client: TestClient) -> dict:
    status = ok_json(client.get("/api/status", headers=AUTH))
    return {
        "goal_m": status["goal"]["position_m"],
        "commanded_m": status["ee"]["commanded_m"],
        "torque": status["torque"],
        "mode": status["mode"],
    }


def holding_at_goal(client: TestClient) -> dict[str, str]:
    """A holder with torque on and a goal set; returns its headers."""
    holder = take_lease(client, "alice", token=TOKEN, sticky=False)
    ok_json(client.post("/api/reset", headers=holder))
    ok_json(client.post("/api/torque", json={"enabled": True}, headers=holder))
    ok_json(client.post("/api/goal", json={"position_m": GOAL}, headers=holder))
    wait_for(
        # to 1e-12 m: the approach's last ticks move it by nanometres, which `unmoved` sees
        lambda: np.allclose(robot(client)["commanded_m"], GOAL, rtol=0, atol=1e-12),
        "the approach to the goal done (commanded at the goal)",
        seen=lambda: robot(client),
    )
    return holder


@pytest.mark.slow
def test_every_command_route_checks_the_lease():
    """A law over /openapi.json: every POST/PUT/PATCH/DELETE route takes the X-Lease header
    of the lease check (require_control), unless it is named in NO_LEASE; a route added
    later without the check fails here."""
    schema = create_app(load_settings()).openapi()
    commands = {}
    for path, item in schema["paths"].items():
        for method, operation in item.items():
            if method in ("post", "put", "patch", "delete"):
                headers = {
                    p["name"].lower()
                    for p in operation.get("parameters", [])
                    if p["in"] == "header"
                }
                commands[(method, path)] = "x-lease" in headers
    named = {("post", path) for path, _ in COMMANDS if "nope" not in path}
    assert named <= set(commands)
    assert commands[("post", "/api/runs/{run_id}/abort")]
    for (method, path), checked in commands.items():
        if path not in NO_LEASE:
            assert checked, f"{method.upper()} {path} does not check the lease"
    assert not commands[("post", "/api/estop")]


@pytest.mark.slow
@pytest.mark.parametrize(("path", "body"), COMMANDS, ids=[p for p, _ in COMMANDS])
def test_a_command_without_the_lease_is_refused_and_nothing_moves(local, path, body):
    holding_at_goal(local)
    before = robot(local)
    for headers in ({**AUTH}, {**AUTH, "X-Client": "alice"}, {**AUTH, "X-Lease": "alice"}):
        response = local.post(path, json=body, headers=headers)
        assert response.status_code == 409, (headers, response.text)
        assert "alice" in response.json()["detail"]
    assert unmoved(before, robot(local)), (before, robot(local))


def test_with_nobody_holding_control_a_command_says_to_take_the_lease(local):
    holder = take_lease(local, token=TOKEN, sticky=False)
    assert local.delete("/api/lease", headers=holder).status_code == 200
    assert ok_json(local.get("/api/lease"))["held"] is False
    response = local.post("/api/torque", json={"enabled": True}, headers=AUTH)
    assert response.status_code == 409
    assert "POST /api/lease" in response.json()["detail"]


def test_knowing_the_holders_name_gives_no_control(local):
    """Issue 14, point 4: the public lease view named the holder, and that name in
    X-Client moved the robot."""
    holder = holding_at_goal(local)
    public = local.get("/api/lease")  # no token needed on loopback
    view = ok_json(public)
    assert view["held"] is True and view["holder"] == "alice"
    assert set(view) == {"held", "holder", "since_s", "idle_s"}
    assert holder["X-Lease"] not in public.text
    before = robot(local)
    impostor = {**AUTH, "X-Client": "alice"}
    moved = local.post("/api/goal", json={"position_m": [0.03, 0.0, -0.25]}, headers=impostor)
    assert moved.status_code == 409, moved.text
    assert local.post("/api/lease", json={"client": "alice"}, headers=AUTH).status_code == 409
    assert unmoved(before, robot(local)), (before, robot(local))
    # the holder itself still commands
    ok_json(local.post("/api/jog", json={"delta_m": [0.0, 0.0, 0.001]}, headers=holder))


def test_taking_over_is_explicit_and_ends_the_old_lease(local):
    alice = holding_at_goal(local)
    since = ok_json(local.get("/api/lease"))["since_s"]
    auth = {"Authorization": f"Bearer {TOKEN}"}
    taken = ok_json(
        local.post("/api/lease", json={"client": "bob", "take_over": True}, headers=auth)
    )
    bob = {**auth, "X-Lease": taken["lease_id"]}
    assert taken["took_over_from"]["holder"] == "alice"  # says whose control it took
    assert taken["took_over_from"]["since_s"] == since
    assert ok_json(local.get("/api/lease"))["holder"] == "bob"
    ok_json(local.post("/api/torque", json={"enabled": True}, headers=bob))
    refused = local.post("/api/torque", json={"enabled": False}, headers=alice)
    assert refused.status_code == 409 and "bob" in refused.json()["detail"]
    assert robot(local)["torque"] is True


def test_commands_need_the_token_as_well_as_the_lease(local):
    holder = holding_at_goal(local)
    lease_only = {"X-Lease": holder["X-Lease"]}
    assert local.post("/api/torque", json={"enabled": False}, headers=lease_only).status_code == 401
    assert robot(local)["torque"] is True


@pytest.mark.slow
def test_e_stop_needs_no_token_and_no_lease(networked):
    holder = holding_at_goal(networked)
    response = networked.post("/api/estop")  # no Authorization, no X-Lease
    assert response.status_code == 200, response.text
    assert robot(networked)["mode"] == "estop"
    assert networked.post("/api/reset").status_code == 401  # clearing it is a command
    ok_json(networked.post("/api/reset", headers=holder))


@pytest.mark.slow
def test_reads_need_the_token_beyond_loopback(networked):
    """Issue 14, point 9: with --host 0.0.0.0 --token, status, runs, run files and the
    lease were readable by anyone."""
    reads = ["/api/status", "/api/telemetry", "/api/lease", "/api/runs", "/api/mav/pose"]
    for path in reads:
        assert networked.get(path).status_code == 401, path
        assert networked.get(path, headers=AUTH).status_code == 200, path
    for path in ("/api/runs/nope", "/api/runs/nope/log.csv", "/api/runs/nope/stats"):
        assert networked.get(path).status_code == 401, path
        assert networked.get(path, headers=AUTH).status_code == 404, path
    # the page, its assets and what it reads to know it must ask for the token stay open
    for path in ("/", "/js/api.js", "/api/info"):
        assert networked.get(path).status_code == 200, path
    assert ok_json(networked.get("/api/info"))["token_required"] is True


def test_reads_on_loopback_need_no_token(local):
    for path in ("/api/status", "/api/lease", "/api/runs"):
        assert local.get(path).status_code == 200, path


@pytest.mark.parametrize("authorization", [TOKEN, f"Token {TOKEN}", f"Basic {TOKEN}", "Bearer"])
def test_only_a_bearer_token_is_accepted(networked, authorization):
    """Issue 14, point 10: a bare token in Authorization was accepted."""
    headers = {"Authorization": authorization}
    assert networked.get("/api/status", headers=headers).status_code == 401
    lease = networked.post("/api/lease", json={"client": "bare"}, headers=headers)
    assert lease.status_code == 401
    scheme_any_case = {"Authorization": f"bearer {TOKEN}"}
    body = {"client": "x", "take_over": True}
    assert networked.post("/api/lease", json=body, headers=scheme_any_case).status_code == 200


def test_giving_back_someone_elses_lease_is_refused_and_changes_nothing(local):
    holder = take_lease(local, "alice", token=TOKEN, sticky=False)
    for wrong in ({**AUTH, "X-Lease": "alice"}, {**AUTH}):
        response = local.delete("/api/lease", headers=wrong)
        assert response.status_code == 409, response.text
    assert ok_json(local.get("/api/lease"))["holder"] == "alice"
    assert local.delete("/api/lease", headers=holder).status_code == 200

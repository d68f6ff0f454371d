"""The page's hold in world through the API (issue 32): the simulated drone started and
stopped as a pose input (POST /api/mav/simulated), its pose in GET /api/mav/pose, and a hold
run on the pose input at a world goal (POST /api/tests/hold source "external") with its
refusals: no fresh pose, a goal outside, a bad field, no lease. In-process, the loop on
simulated time; the drone's feed and the pose's age are the station's clock."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    # the pose's age is the station's clock while the loop runs on simulated time, faster
    # and in bursts: a wide margin before a pose is stale or lost (staleness is not the
    # point here: tests/world/test_hold_api.py and the page's test see it)
    world = {"stale_after_s": 1.0, "lost_after_s": 5.0}
    with make_client(tmp_path_factory.mktemp("runs"), world=world) as test_client:
        take_lease(test_client)
        yield test_client
        test_client.post("/api/mav/simulated", json={"running": False})


def _pose(client) -> dict:
    return ok_json(client.get("/api/mav/pose"))


def _fly(client, **profile) -> dict:
    # the drone is refused while another source's pose is fresh (it would stand in for it)
    wait_for(
        lambda: (p := _pose(client))["state"] != "ok" or p["source"] == "simulated",
        "the poses the last test posted no longer fresh",
    )
    answer = ok_json(client.post("/api/mav/simulated", json={"running": True, **profile}))
    wait_for(
        lambda: _pose(client)["source"] == "simulated" and _pose(client)["state"] == "ok",
        "the simulated drone's pose, fresh",
    )
    return answer


def _tool_in_world(client) -> np.ndarray:
    """The tool tip in the world [m] as GET /api/mav/pose says it."""
    return np.asarray(_pose(client)["tool_world_m"])


def _now() -> float:
    """A pose's time: the station's clock, as the simulated drone's feed stamps its poses
    (a pose older than the latest kept one is dropped)."""
    return time.monotonic()


def _runs(client) -> int:
    return len(ok_json(client.get("/api/runs")))


def test_the_simulated_drone_feeds_the_pose_input_and_stops(client):
    answer = _fly(client, seed=5, drift_m=0.01, tilt_deg=1.0, rate_hz=50.0)
    assert answer["running"] is True and answer["params"]["seed"] == 5
    pose = _pose(client)
    assert pose["simulated"]["running"] and pose["simulated"]["params"]["drift_m"] == 0.01
    # the drone hovers at 1.5 m with centimetres of drift; its attitude is a unit quaternion
    assert np.linalg.norm(np.subtract(pose["position_m"], [0.0, 0.0, 1.5])) < 0.1
    assert np.linalg.norm(pose["quaternion"]) == pytest.approx(1.0, abs=1e-9)
    wait_for(lambda: _pose(client)["rate_hz"] > 10.0, "a pose rate measured")
    ok_json(client.post("/api/mav/simulated", json={"running": False}))
    assert _pose(client)["simulated"]["running"] is False
    wait_for(lambda: _pose(client)["state"] in ("stale", "lost"), "the pose stale once stopped")
    assert _pose(client)["source"] == "simulated"  # the last sample's source stays said


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"running": True, "rate_hz": 0}, "rate_hz"),
        ({"running": True, "drift_m": "a lot"}, "drift_m"),
        ({"running": True, "drift_m": 0.5}, "drift_m"),
        ({"running": True, "wind": 3}, "wind"),
        ({}, "running"),
    ],
)
def test_a_bad_drone_profile_is_refused_naming_the_field_and_nothing_flies(client, body, field):
    client.post("/api/mav/simulated", json={"running": False})
    response = client.post("/api/mav/simulated", json=body)
    assert response.status_code == 422 and field in response.json()["detail"], response.text
    assert _pose(client)["simulated"]["running"] is False


def test_starting_the_drone_needs_the_lease(client):
    client.post("/api/mav/simulated", json={"running": False})
    response = client.post(
        "/api/mav/simulated", json={"running": True}, headers={"X-Lease": "not-the-lease"}
    )
    assert response.status_code == 409, response.text
    assert _pose(client)["simulated"]["running"] is False


def test_the_tool_in_the_world_is_the_tip_through_the_pose_and_the_mount(client):
    """A drone posted still, tilted and turned: GET /api/mav/pose's tool in the world is the
    resting tip carried through the drone's pose and the mount, by hand."""
    client.post("/api/mav/simulated", json={"running": False})
    client.post("/api/reset")
    ok_json(client.post("/api/torque", json={"enabled": True}))
    ok_json(client.post("/api/goal", json={"position_m": [0.02, 0.0, -0.24]}))
    tip = lambda: np.asarray(ok_json(client.get("/api/status"))["ee"]["position_m"])  # noqa: E731
    wait_for(lambda: np.linalg.norm(tip() - [0.02, 0.0, -0.24]) < 2e-4, "the arm at its goal")
    # 30 deg about z, where the drone was last (a pose further than max_jump_m is dropped)
    at = _pose(client)["position_m"] or [0.0, 0.0, 1.5]
    half = np.radians(30.0) / 2
    drone = {"position": at, "quaternion": [np.cos(half), 0, 0, np.sin(half)]}
    assert ok_json(client.post("/api/mav/pose", json={"t": _now(), **drone}))["accepted"]
    pose = _pose(client)
    assert pose["mount_position_m"] == [0.0, 0.0, -0.08]  # the default mount, no turn
    here = tip()
    c, s = np.cos(2 * half), np.sin(2 * half)
    turned = [c * here[0] - s * here[1], s * here[0] + c * here[1], here[2] - 0.08]
    by_hand = np.add(at, turned)
    np.testing.assert_allclose(pose["tool_world_m"], by_hand, atol=2e-4)  # the tip rests


def test_a_client_cannot_say_its_pose_came_from_the_simulated_drone(client):
    at = _pose(client)["position_m"] or [0.0, 0.0, 1.5]
    pose = {"t": _now(), "position": at, "quaternion": [1, 0, 0, 0]}
    refused = client.post("/api/mav/pose", json={**pose, "source": "simulated"})
    assert refused.status_code == 422 and "source" in refused.text
    with client.websocket_connect("/api/mav/pose") as ws:
        ws.send_json({**pose, "source": "simulated"})
        ws.send_json({**pose, "t": _now(), "quaternion": [2, 0, 0, 0]})  # answered: synced
        assert "error" in ws.receive_json()
    assert _pose(client)["source"] == "websocket"


def test_a_hold_on_the_pose_input_is_refused_without_a_fresh_pose_and_nothing_moves(client):
    client.post("/api/mav/simulated", json={"running": False})
    wait_for(lambda: _pose(client)["state"] != "ok", "no fresh pose")
    before, mode = _runs(client), ok_json(client.get("/api/status"))["mode"]
    response = client.post(
        "/api/tests/hold", json={"source": "external", "position_m": [0.0, 0.0, 1.2]}
    )
    assert response.status_code == 409 and response.json()["detail"].startswith("source: ")
    assert _runs(client) == before and ok_json(client.get("/api/status"))["mode"] == mode


def test_a_bad_or_outside_world_goal_is_refused_naming_position_m(client):
    client.post("/api/reset")
    ok_json(client.post("/api/torque", json={"enabled": True}))
    _fly(client, drift_m=0.0, tilt_deg=0.0, yaw_deg=0.0, gust_m=0.0)
    before = _runs(client)
    for goal in (["x", 0.0, 1.2], [0.0, 0.0], [0.0, 0.0, True], "here"):
        body = {"source": "external", "position_m": goal}
        response = client.post("/api/tests/hold", json=body)
        assert response.status_code == 422 and "position_m" in response.json()["detail"]
    outside = (_tool_in_world(client) + [0.0, 0.0, 0.5]).tolist()  # half a metre up: outside
    response = client.post("/api/tests/hold", json={"source": "external", "position_m": outside})
    assert response.status_code == 422, response.text
    assert response.json()["detail"].startswith("position_m: outside the workspace")
    assert _runs(client) == before and ok_json(client.get("/api/status"))["mode"] != "hold-world"


@pytest.mark.slow  # an end-to-end run of seconds
def test_a_hold_on_the_pose_input_runs_at_the_world_goal_with_world_stats(client):
    """A drone 10 mm off and turned 10 deg, its pose posted by the test as each wait polls
    (the loop runs on simulated time, faster than the station's clock that ages a pose):
    the hold brings the tool to a world goal 5 mm from where it is, and the run's world
    stats, from the tool in the world as the pose input says, show it there."""
    client.post("/api/mav/simulated", json={"running": False})
    client.post("/api/reset")
    ok_json(client.post("/api/torque", json={"enabled": True}))
    ok_json(client.post("/api/goal", json={"position_m": [0.0, 0.0, -0.24]}))
    yaw = np.radians(10.0)
    still = {"position": [0.01, 0.0, 1.5], "quaternion": [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]}

    def post_pose() -> None:
        client.post("/api/mav/pose", json={"t": _now(), **still})

    post_pose()
    wait_for(lambda: post_pose() or _pose(client)["state"] == "ok", "a fresh pose")
    goal = (_tool_in_world(client) + [0.005, 0.0, 0.0]).tolist()
    body = {"source": "external", "position_m": goal, "duration_s": 1.5}
    run_id = ok_json(client.post("/api/tests/hold", json=body))["run_id"]

    def ended() -> bool:
        post_pose()
        return ok_json(client.get(f"/api/runs/{run_id}"))["state"] != "running"

    wait_for(ended, "the hold run's end")
    run = ok_json(client.get(f"/api/runs/{run_id}"))
    assert run["state"] == "done" and run["kind"] == "hold", run["reason"]
    assert run["params"]["source"] == "external" and run["params"]["position_m"] == goal
    world = run["stats"]["world"]  # the tool in the world as the pose input says
    for axis in "xyz":  # at the goal, not where it started 5 mm away
        assert world[axis]["rmse_m"] < 0.001, world
    assert world["outside_s"] == 0.0


def test_a_heading_without_a_wrist_is_refused_naming_heading_rad(client):
    client.post("/api/reset")
    ok_json(client.post("/api/torque", json={"enabled": True}))
    _fly(client, drift_m=0.0, tilt_deg=0.0, yaw_deg=0.0, gust_m=0.0)
    before = _runs(client)
    body = {"source": "external", "position_m": _tool_in_world(client).tolist()}
    response = client.post("/api/tests/hold", json={**body, "heading_rad": 0.5})
    assert response.status_code == 422 and "heading_rad" in response.json()["detail"]
    assert _runs(client) == before and ok_json(client.get("/api/status"))["mode"] != "hold-world"
    client.post("/api/mav/simulated", json={"running": False})

"""Every bad input is a 4xx with a clear message, never a 500, and the loop keeps running."""

from __future__ import annotations

import pytest

from tests.support.app_client import ticks
from tests.support.wait import wait_for

BAD_GOAL_BODIES = [
    ('{"position_m": [NaN, 0, -0.2]}', "finite"),
    ('{"position_m": [Infinity, 0, -0.2]}', "finite"),
    ('{"position_m": [-Infinity, 0, -0.2]}', "finite"),
    ('{"position_m": ["a", 0, -0.2]}', "position_m.0"),
    ('{"position_m": [0, 0]}', "position_m"),
    ('{"position_m": [0, 0, -0.2, 1]}', "position_m"),
    ('{"position_m": [1e300, 0, -0.2]}', "outside the workspace"),
    ('{"position_m": [0.5, 0, -0.2]}', "nearest reachable point"),
    ('{"position_m": [0, 0, 0.1]}', "outside the workspace"),
    ('{"position_m": "0,0,-0.2"}', "position_m"),
    ('{"position_m": [0, 0, -0.2], "frame": "world"}', "frame"),
    ('{"position_m": [0, 0, -0.2], "speed": 3}', "speed"),
    ("{}", "position_m"),
    ("not json", "JSON"),
    ("[1, 2, 3]", "body"),
]


@pytest.mark.slow
@pytest.mark.parametrize(("body", "mentions"), BAD_GOAL_BODIES)
def test_bad_goals_are_422_with_a_clear_detail(fresh, body, mentions):
    before = ticks(fresh)
    response = fresh.post("/api/goal", content=body, headers={"content-type": "application/json"})
    assert response.status_code == 422, response.text
    assert mentions.lower() in response.json()["detail"].lower()
    wait_for(lambda: ticks(fresh) > before, "the loop to keep ticking")


def test_unreachable_goal_names_a_reachable_nearest_point(fresh):
    from kinematics import THESIS_DELTA

    response = fresh.post("/api/goal", json={"position_m": [0.4, 0.0, -0.2]})
    assert response.status_code == 422, response.text
    assert THESIS_DELTA.reachable(response.json()["nearest_m"])


@pytest.mark.parametrize(
    ("path", "body"),
    [
        ("/api/jog", {"delta_m": [float("nan"), 0, 0]}),
        ("/api/jog", {"delta_m": [0, 0]}),
        ("/api/move", {"position_m": [0, 0, -0.2], "joints_rad": [0, 0, 0]}),
        ("/api/move", {}),
        ("/api/move", {"joints_rad": [3.0, 0, 0]}),
        ("/api/move", {"position_m": [0, 0, -0.2], "duration_s": -1}),
        ("/api/move", {"position_m": [0, 0, -0.2], "space": "polar"}),
        ("/api/torque", {"enabled": "maybe"}),
        ("/api/torque", {}),
        ("/api/lease", {"client": ""}),
    ],
)
def test_other_bad_bodies_are_422(fresh, path, body):
    import json

    text = json.dumps(body)  # NaN goes out as the JS literal NaN
    response = fresh.post(path, content=text, headers={"content-type": "application/json"})
    assert response.status_code == 422, response.text
    assert response.json()["detail"]


def test_motion_with_torque_off_is_409(fresh):
    response = fresh.post("/api/goal", json={"position_m": [0.0, 0.0, -0.22]})
    assert response.status_code == 409, response.text
    assert "torque" in response.json()["detail"]
    response = fresh.post("/api/jog", json={"delta_m": [0.01, 0.0, 0.0]})
    assert response.status_code == 409


@pytest.mark.slow
def test_unknown_paths_and_methods_are_4xx(fresh):
    assert fresh.get("/api/nope").status_code == 404
    assert fresh.get("/api/goal").status_code in (404, 405)  # the dashboard mount answers GETs

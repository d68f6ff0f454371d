"""GET /api/workspace/section and /nearest (the page's 2D view) and /api/status's loop light."""

from __future__ import annotations

import numpy as np
import pytest

from app.control.errors import GoalRejected
from tests.support.wait import ok_json

SECTIONS = [("xy", -0.24), ("xy", -0.33), ("xz", 0.0), ("xz", 0.05), ("yz", -0.03)]


def cells(body: dict) -> tuple[np.ndarray, np.ndarray]:
    """(points (n_v, n_u, 3) [m], reachable (n_v, n_u)) of a section's answer."""
    u, v = np.array(body["u_m"]), np.array(body["v_m"])
    iu, iv, il = ("xyz".index(a) for a in body["axes"])
    uu, vv = np.meshgrid(u, v, indexing="xy")
    points = np.empty((*uu.shape, 3))
    points[..., iu], points[..., iv], points[..., il] = uu, vv, body["at_m"]
    reachable = np.array([[c == "1" for c in row] for row in body["reachable"]])
    return points, reachable


@pytest.mark.slow
@pytest.mark.parametrize(("plane", "level"), SECTIONS)
def test_a_section_marks_exactly_what_the_gate_accepts(client, plane, level):
    body = ok_json(client.get("/api/workspace/section", params={"plane": plane, "at_m": level}))
    assert body["plane"] == plane and body["at_m"] == pytest.approx(level, abs=5e-4)
    points, reachable = cells(body)
    assert reachable.any() and not reachable.all()  # the cut meets the boundary
    frame = (reachable[0], reachable[-1], reachable[:, 0], reachable[:, -1])
    assert not any(side.any() for side in frame)  # the grid frames the region, ceiling too
    gate = client.app.state.controller.gate
    rng = np.random.default_rng(17)
    inside, outside = points[reachable], points[~reachable]
    for point in inside[rng.choice(len(inside), 40)]:
        assert gate_accepts(gate, point), point  # the gate's own checks, point by point
        assert gate.robot.ik(point).ok, point  # so the legs reach it
    for point in outside[rng.choice(len(outside), 40)]:
        assert not gate_accepts(gate, point), point


def gate_accepts(gate, point) -> bool:
    """The gate takes ``point`` as a goal from a working posture (its knee-out joints)."""
    try:
        gate.check_point(point)
        gate.solve(point, gate.robot.ik(point).joints)
    except GoalRejected:
        return False
    return True


def test_a_level_is_rounded_to_a_millimetre_and_cached(client):
    first = ok_json(client.get("/api/workspace/section", params={"plane": "xy", "at_m": -0.2403}))
    again = ok_json(client.get("/api/workspace/section", params={"plane": "xy", "at_m": -0.2398}))
    assert first["at_m"] == again["at_m"] == pytest.approx(-0.240)
    assert first == again


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"plane": "xw", "at_m": -0.24}, "plane"),
        ({"plane": "XY", "at_m": -0.24}, "plane"),
        ({"at_m": -0.24}, "plane"),
        ({"plane": "xy", "at_m": "nan"}, "at_m"),
        ({"plane": "xy", "at_m": "inf"}, "at_m"),
        ({"plane": "xy", "at_m": "-0,24"}, "at_m"),
        ({"plane": "xy", "at_m": 5.0}, "at_m"),
        ({"plane": "xy"}, "at_m"),
    ],
)
def test_a_bad_section_request_is_422_naming_the_field(client, params, field):
    response = client.get("/api/workspace/section", params=params)
    assert response.status_code == 422, response.text
    assert f"query.{field}" in response.json()["detail"]


def nearest(client, point) -> dict:
    params = dict(zip(("x_m", "y_m", "z_m"), point, strict=True))
    return ok_json(client.get("/api/workspace/nearest", params=params))


def test_nearest_is_the_point_itself_when_the_gate_takes_it(client):
    answer = nearest(client, [0, 0, -0.24])
    assert answer["inside"] and answer["nearest_m"] == [0, 0, -0.24] and answer["distance_m"] == 0


def test_nearest_is_the_goals_422_point_and_the_gate_takes_it(client):
    gate = client.app.state.controller.gate
    goal = [0.0, 0.01, -0.5]  # below the workspace: its nearest point is on the bottom
    answer = nearest(client, goal)
    refused = client.post("/api/goal", json={"position_m": goal})
    assert refused.status_code == 422 and not answer["inside"]
    assert answer["nearest_m"] == refused.json()["nearest_m"]  # one rule for both
    # the workspace's nearest point, moved 0.02 mm inwards (0.01 mm rounding stays inside)
    np.testing.assert_allclose(answer["nearest_m"], gate.nearest(np.array(goal)), atol=2.1e-5)
    rounded = np.round(np.array(answer["nearest_m"]), 5)
    assert gate_accepts(gate, rounded)
    point = np.array(answer["nearest_m"])
    assert gate_accepts(gate, point)
    assert answer["distance_m"] == pytest.approx(np.linalg.norm(point - goal))
    # nothing nearer is accepted: a little towards the goal from it is outside
    assert not gate.inside(point + 1e-4 * (np.array(goal) - point) / answer["distance_m"])


@pytest.mark.parametrize("goal", [[0.3, 0.02, -0.24], [0.3, 0.05, -0.24], [0, 0, 0.1]])
def test_nearest_is_a_point_the_gate_takes_where_the_workspaces_breaks_a_joint_limit(client, goal):
    """At z = -240 mm the workspace's nearest point to (300, 20) mm needs joint 2 past its
    limit: the gate would refuse it in turn; /nearest and the 422 offer one it takes."""
    gate = client.app.state.controller.gate
    assert not gate_accepts(gate, gate.nearest(np.array(goal)))
    refused = client.post("/api/goal", json={"position_m": goal})
    assert refused.status_code == 422
    assert gate_accepts(gate, np.array(refused.json()["nearest_m"]))
    answer = nearest(client, goal)
    assert not answer["inside"] and gate_accepts(gate, np.array(answer["nearest_m"]))


def test_nearest_refuses_a_bad_coordinate_naming_it(client):
    response = client.get("/api/workspace/nearest", params={"x_m": 0, "y_m": "nan", "z_m": -0.2})
    assert response.status_code == 422 and "query.y_m" in response.json()["detail"]


def test_the_status_carries_the_loop_light_judged_on_the_last_10_s(client):
    loop = ok_json(client.get("/api/status"))["loop"]
    light, window = loop["health"], loop["last_10s"]
    assert light["level"] in ("green", "amber", "red", "unknown")
    assert light["window_s"] == 10.0
    assert light["ticks"] == window["ticks"] and light["rate_hz"] == window["measured_hz"]
    assert light["longest_gap_ms"] == window["longest_gap_ms"] >= 0
    assert (light["level"] == "green") == (light["reasons"] == [] and light["ticks"] >= 2) or (
        light["level"] == "unknown"
    )

"""GET /api/workspace/section and /nearest (the page's 2D view) and /api/status's loop light."""

from __future__ import annotations

import numpy as np
import pytest

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
        assert gate.inside(point), point  # the same rule, point by point
        assert gate.robot.ik(point).ok, point  # and the legs reach it
    for point in outside[rng.choice(len(outside), 40)]:
        assert not gate.inside(point), point


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


def test_nearest_is_the_point_inside_and_the_goals_422_outside(client):
    gate = client.app.state.controller.gate
    inside = ok_json(
        client.get("/api/workspace/nearest", params={"x_m": 0, "y_m": 0, "z_m": -0.24})
    )
    assert inside["inside"] and inside["nearest_m"] == [0, 0, -0.24] and inside["distance_m"] == 0
    goal = [0.3, 0.05, -0.24]
    params = dict(zip(("x_m", "y_m", "z_m"), goal, strict=True))
    outside = ok_json(client.get("/api/workspace/nearest", params=params))
    nearest = np.array(outside["nearest_m"])
    assert not outside["inside"] and gate.inside(nearest)
    assert outside["distance_m"] == pytest.approx(np.linalg.norm(nearest - goal))
    refused = client.post("/api/goal", json={"position_m": goal})
    assert refused.status_code == 422
    np.testing.assert_allclose(refused.json()["nearest_m"], nearest, atol=1e-9)
    # nothing nearer is accepted: points a little towards the goal from it are outside
    assert not gate.inside(nearest + 1e-4 * (np.array(goal) - nearest) / outside["distance_m"])


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

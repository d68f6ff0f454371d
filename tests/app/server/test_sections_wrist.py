"""The 2D view's sections and "go to nearest" with a tool off the wrist's axis (issue 19):
points are tool tips at a wrist angle phi, so the accepted region is the platform's moved
by the offset turned by phi.

Laws: a tip at phi is accepted exactly when the tool-less gate accepts its platform point
(tip - Rz(phi) d); a section at phi marks what the gate's own checks accept at phi, point
by point; the nearest point offered at phi passes the gate at phi (and differs from the one
at phi = 0); the view's extent holds the region at every angle. API: ``phi_rad`` outside the
wrist's limits, or non-zero without a wrist, is a 422 naming it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient
from hypothesis import given, settings
from hypothesis import strategies as st

from app.config import load_settings
from app.control.commands import CommandContext
from app.control.errors import GoalRejected
from app.server import sections
from kinematics import Tool
from tests.support.app_client import make_client
from tests.support.wait import ok_json

PLAIN = CommandContext.from_settings(load_settings()).gate
OFFSET = np.array([0.04, 0.0, -0.05])  # 4 cm to the side
TOOLED = dataclasses.replace(
    PLAIN, tool=Tool(offset_m=OFFSET, wrist=True), wrist_min_rad=-math.pi, wrist_max_rad=math.pi
)
TIPS = st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3), st.floats(-0.5, 0.0)).map(np.array)


def _rz(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _gate_accepts(gate, tip, phi) -> bool:
    try:
        gate.check_point(tip, phi)
        gate.solve(tip, gate.robot.ik(gate.platform(tip, phi)).joints, phi)
    except GoalRejected:
        return False
    return True


@settings(max_examples=40, deadline=None)
@given(tip=TIPS, phi=st.floats(-math.pi, math.pi))
def test_a_tip_at_phi_is_accepted_as_its_platform_point_is(tip, phi):
    platform = tip - _rz(phi) @ OFFSET
    assert (
        sections.accepted(TOOLED, tip[None], phi)[0] == sections.accepted(PLAIN, platform[None])[0]
    )


@pytest.mark.parametrize("phi", [0.0, 1.2, -2.5])
def test_a_section_at_phi_marks_what_the_gate_accepts_there(phi):
    cut = sections.section(TOOLED, "xy", -0.29, phi)
    assert cut.phi_rad == pytest.approx(phi, abs=math.radians(0.5))
    uu, vv = np.meshgrid(cut.u_m, cut.v_m, indexing="xy")
    points = np.stack([uu, vv, np.full_like(uu, cut.level_m)], axis=-1)
    inside, outside = points[cut.reachable], points[~cut.reachable]
    assert len(inside) > 50 and len(outside) > 50
    rng = np.random.default_rng(3)
    for tip in inside[rng.choice(len(inside), 25)]:
        assert _gate_accepts(TOOLED, tip, cut.phi_rad), tip
    for tip in outside[rng.choice(len(outside), 25)]:
        assert not _gate_accepts(TOOLED, tip, cut.phi_rad), tip
    frame = (cut.reachable[0], cut.reachable[-1], cut.reachable[:, 0], cut.reachable[:, -1])
    assert not any(side.any() for side in frame)  # the extent holds it at this angle too


def test_the_region_turns_with_the_wrist():
    at_0, at_pi = (
        sections.section(TOOLED, "xy", -0.29, 0.0),
        sections.section(TOOLED, "xy", -0.29, math.pi),
    )
    u = at_0.u_m
    centre = lambda cut: float((cut.reachable * u[None, :]).sum() / cut.reachable.sum())  # noqa: E731
    # the tip circles the platform centre: half a turn moves the region by twice the offset
    assert centre(at_0) - centre(at_pi) == pytest.approx(2 * OFFSET[0], abs=0.004)


@pytest.mark.parametrize("phi", [0.0, 1.0, -2.0])
def test_the_nearest_point_offered_at_phi_passes_the_gate_at_phi(phi):
    goal = np.array([0.3, 0.05, -0.27])
    offered = sections.nearest(TOOLED, goal, phi)
    assert _gate_accepts(TOOLED, offered, phi)
    assert _gate_accepts(TOOLED, np.round(offered, 5), phi)  # as the page shows and sends it
    if phi != 0.0:
        assert not _gate_accepts(TOOLED, sections.nearest(TOOLED, goal, 0.0), phi)


@pytest.fixture(scope="module")
def wristed(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("sections-wrist")
    wrist = {"enabled": True, "min_angle_rad": -1.5, "max_angle_rad": 1.5}
    with make_client(folder, tool={"offset_m": OFFSET.tolist()}, wrist=wrist) as client:
        yield client


@pytest.mark.slow
def test_the_api_cuts_and_offers_at_the_asked_wrist_angle(wristed):
    params = {"plane": "xy", "at_m": -0.29, "phi_rad": 1.0}
    body = ok_json(wristed.get("/api/workspace/section", params=params))
    assert body["phi_rad"] == pytest.approx(1.0, abs=math.radians(0.5))
    gate = wristed.app.state.controller.gate
    expected = sections.section(gate, "xy", -0.29, 1.0)
    assert body["reachable"] == ["".join("1" if c else "0" for c in r) for r in expected.reachable]
    goal = {"x_m": 0.3, "y_m": 0.05, "z_m": -0.27, "phi_rad": 1.0}
    answer = ok_json(wristed.get("/api/workspace/nearest", params=goal))
    assert not answer["inside"] and _gate_accepts(gate, np.array(answer["nearest_m"]), 1.0)


@pytest.mark.parametrize("phi", [2.0, -1.6])
def test_a_wrist_angle_beyond_the_limits_is_422_naming_it(wristed, phi):
    for path, params in (
        ("/api/workspace/section", {"plane": "xy", "at_m": -0.29}),
        ("/api/workspace/nearest", {"x_m": 0.0, "y_m": 0.0, "z_m": -0.29}),
    ):
        response = wristed.get(path, params={**params, "phi_rad": phi})
        assert response.status_code == 422, response.text
        assert "phi_rad" in response.json()["detail"], response.text


@pytest.mark.slow
def test_without_a_wrist_a_turned_tip_is_422(client):
    response = client.get(
        "/api/workspace/section", params={"plane": "xy", "at_m": -0.24, "phi_rad": 0.3}
    )
    assert response.status_code == 422 and "phi_rad" in response.json()["detail"]

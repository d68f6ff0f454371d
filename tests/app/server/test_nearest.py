"""The nearest reachable point offered for a refused goal (app/server/sections.py
``nearest``: the 422's ``nearest_m`` and GET /api/workspace/nearest) is one the gate takes,
and not farther than needed.

The law, for goals outside the workspace, beyond a joint limit and above the ceiling: the
offered point passes the gate's own checks (``Gate.check_point`` then ``Gate.solve`` from the
home posture, as a goal sent from there would), and no point of a GRID_M grid that the gate
accepts lies nearer the goal by more than TOLERANCE_M (brute force over the ball around the
goal). A goal the gate takes is offered as itself.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.config import Settings
from app.control.commands import CommandContext
from app.control.errors import GoalRejected
from app.server import sections

GRID_M = 2e-3  # the brute-force grid's step
TOLERANCE_M = 1e-3  # the offered point may be this much farther than the grid's nearest
HOME_M = np.array([0.0, 0.0, -0.24])

# (goal [m], what refuses it); the distances to the accepted set are 5 to 90 mm
GOALS = [
    ([0.30, 0.02, -0.24], "joint 2 limit: the workspace's nearest point breaks it"),
    ([0.30, 0.05, -0.24], "joint limit"),
    ([-0.10, 0.25, -0.30], "joint limit"),
    ([0.229, -0.064, -0.225], "joint limit, near the workspace"),
    ([0.0, 0.0, -0.05], "the ceiling"),
    ([-0.154, -0.01, -0.01], "above the ceiling, off axis"),
    ([0.05, 0.10, -0.45], "below the workspace"),
    ([0.0, 0.01, -0.50], "below the workspace, on the axis"),
    ([0.065, -0.168, -0.08], "outside, high"),
    ([-0.033, -0.256, -0.298], "outside the side"),
]


@pytest.fixture(scope="module")
def gate():
    return CommandContext.from_settings(Settings()).gate


def gate_takes(gate, point: np.ndarray) -> str | None:
    """None when the gate takes ``point`` as a goal from the home posture, else why not."""
    near = gate.robot.ik(HOME_M).joints
    try:
        gate.solve(gate.check_point(point), near)
    except GoalRejected as exc:
        return str(exc)
    return None


def nearest_on_grid(gate, goal: np.ndarray, radius_m: float) -> float:
    """The distance [m] from ``goal`` to the nearest accepted point of a GRID_M grid within
    ``radius_m`` of it (inf when none)."""
    axis = np.arange(-radius_m, radius_m + GRID_M, GRID_M)
    offsets = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    offsets = offsets[np.linalg.norm(offsets, axis=1) <= radius_m]
    ok = sections.accepted(gate, goal + offsets)
    return float(np.linalg.norm(offsets[ok], axis=1).min()) if ok.any() else np.inf


@pytest.mark.slow
@pytest.mark.parametrize(("goal", "why"), GOALS, ids=[g[1] for g in GOALS])
def test_the_offered_point_is_taken_by_the_gate_and_no_farther_than_needed(gate, goal, why):
    goal = np.array(goal)
    assert gate_takes(gate, goal) is not None, f"the goal ({why}) must be refused"
    offered = sections.nearest(gate, goal)
    assert gate_takes(gate, offered) is None, (offered, gate_takes(gate, offered))
    assert gate_takes(gate, np.round(offered, 5)) is None  # as a page shows and sends it
    distance = float(np.linalg.norm(offered - goal))
    grid = nearest_on_grid(gate, goal, distance)
    assert distance <= grid + TOLERANCE_M, (why, distance, grid)


@pytest.mark.slow  # seeded goals, a nearest-point search each
def test_random_goals_beyond_the_joint_limits_get_a_point_the_gate_takes(gate):
    """Many goals inside the workspace but refused by a joint limit or the singularity
    margin, and many outside it: each offered point is taken."""
    rng = np.random.default_rng(5)
    candidates = rng.uniform([-0.35, -0.35, -0.5], [0.35, 0.35, 0.0], (400, 3))
    refused = candidates[~sections.accepted(gate, candidates)]
    beyond_limits = refused[sections.inside(gate, refused)]
    assert len(beyond_limits) >= 5  # the case the workspace alone gets wrong is sampled
    for goal in [*beyond_limits[:15], *refused[~sections.inside(gate, refused)][:15]]:
        offered = sections.nearest(gate, goal)
        assert gate_takes(gate, offered) is None, (goal, offered, gate_takes(gate, offered))


def test_a_goal_the_gate_takes_is_offered_as_itself(gate):
    np.testing.assert_array_equal(sections.nearest(gate, HOME_M), HOME_M)


@pytest.mark.slow
def test_the_422_offers_the_same_point_for_a_goal_beyond_a_joint_limit(client):
    """A goal inside the workspace that only a joint limit refuses now gets a nearest_m too
    (it had none), and it is the point /nearest offers."""
    gate = client.app.state.controller.gate
    rng = np.random.default_rng(5)
    candidates = rng.uniform([-0.35, -0.35, -0.5], [0.35, 0.35, 0.0], (400, 3))
    goal = candidates[sections.inside(gate, candidates) & ~sections.accepted(gate, candidates)][0]
    response = client.post("/api/goal", json={"position_m": goal.tolist()})
    assert response.status_code == 422, response.text
    body = response.json()
    assert "nearest reachable point" in body["detail"]
    assert gate_takes(gate, np.array(body["nearest_m"])) is None
    np.testing.assert_allclose(body["nearest_m"], sections.nearest(gate, goal))


@pytest.mark.slow  # a nearest-point search per goal, twice
def test_the_cli_and_the_api_offer_the_same_point_and_the_gate_takes_it(client, capsys):
    """Issue 32 point 6, a property over seeded random goals the gate refuses (outside the
    workspace, beyond a joint limit, above the ceiling): ``deltadash ik``'s ``nearest_m``
    and GET /api/workspace/nearest's are the same point, and the gate takes it as a goal."""
    import json

    from app.cli import main

    gate = client.app.state.controller.gate
    rng = np.random.default_rng(32)
    candidates = rng.uniform([-0.35, -0.35, -0.5], [0.35, 0.35, 0.0], (300, 3))
    accepted = sections.accepted(gate, candidates)
    for goal in candidates[accepted][:5]:  # what the gate takes, ik answers (exit 0)
        assert main(["ik", *map(repr, goal.tolist()), "--si", "--json"]) == 0
        assert "nearest_m" not in json.loads(capsys.readouterr().out)
    refused = candidates[~accepted]
    inside = sections.inside(gate, refused)
    # beyond a joint limit or the singularity margin inside the workspace, and outside it
    goals = [*refused[inside][:6], *refused[~inside][:6]]
    assert len(goals) == 12
    for goal in goals:
        assert main(["ik", *map(repr, goal.tolist()), "--si", "--json"]) == 1
        cli = json.loads(capsys.readouterr().out)["nearest_m"]
        params = dict(zip(("x_m", "y_m", "z_m"), goal.tolist(), strict=True))
        api = client.get("/api/workspace/nearest", params=params).json()
        assert api["inside"] is False
        np.testing.assert_allclose(cli, api["nearest_m"], atol=1e-9)
        assert gate_takes(gate, np.array(cli)) is None, (goal, cli, gate_takes(gate, cli))

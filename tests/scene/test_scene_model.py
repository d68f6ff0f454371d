"""The scene follows the controller's robot model: after a geometry calibration's apply
(``Controller.use_model``) it draws the fitted robot's links and reachable volume, and a
drag is clamped onto the fitted workspace. Its own app: the model changes here."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.scene.geometry import robot_lines
from kinematics import THESIS_DELTA, PerLegRotaryDelta
from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import WAIT_S, wait_for

SHORT_RODS = PerLegRotaryDelta.from_symmetric(THESIS_DELTA, l=(0.2410, 0.2415, 0.2405))


@pytest.fixture(scope="module")
def app_client(tmp_path_factory) -> Iterator[TestClient]:
    with make_client(tmp_path_factory.mktemp("runs"), server={"scene": True}) as client:
        take_lease(client)
        yield client


@pytest.mark.slow
def test_the_scene_draws_and_clamps_with_the_model_in_use(app_client) -> None:
    controller, scene = app_client.app.state.controller, app_client.app.state.scene
    controller.set_torque(True).result(timeout=WAIT_S)
    scene.update(time.monotonic())
    lowest_before = float(scene.workspace.mesh.vertices[:, 2].min())

    controller.use_model(SHORT_RODS, (0.0, 0.0, 0.0), "calibration cal-test").result(WAIT_S)
    scene.update(time.monotonic())
    assert scene.robot.robot is SHORT_RODS and scene.ghost.robot is SHORT_RODS
    drawn = scene.robot._joints
    expected = robot_lines(SHORT_RODS, drawn)
    np.testing.assert_allclose(scene.robot.rods.points, expected.rods.reshape(6, 2, 3), atol=1e-6)
    # the reachable volume is meshed again: the rods are 1.5 to 2.5 mm shorter
    lowest = float(scene.workspace.mesh.vertices[:, 2].min())
    assert 1e-3 < lowest - lowest_before < 3e-3, (lowest_before, lowest)

    sent = scene.goals.drag_to(np.array([0.0, 0.0, -0.6]), final=True)
    np.testing.assert_allclose(sent, controller.gate.nearest(np.array([0.0, 0.0, -0.6])))
    assert SHORT_RODS.reachable(sent, margin=controller.gate.margin_m - 1e-9)
    wait_for(lambda: np.allclose(controller.snapshot().goal_m, sent), "the clamped goal")

"""The scene's goal marker is the loop's setpoint: it follows the goal, and is hidden while
there is none (torque off), instead of floating where the last goal was."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.support.wait import WAIT_S, wait_for


@pytest.mark.slow
def test_marker_follows_the_setpoint_and_hides_without_one(scene):
    goals, controller = scene.goals, scene.controller
    point = np.array([0.02, -0.01, -0.25])
    goals.drag_to(point, final=True)
    wait_for(lambda: np.allclose(controller.snapshot().goal_m, point), "the goal in the loop")
    goals.update(controller.snapshot(), time.monotonic())
    assert goals.marker.visible
    np.testing.assert_allclose(goals.marker.position, point, atol=1e-9)

    controller.set_torque(False).result(timeout=WAIT_S)
    assert not np.isfinite(controller.snapshot().goal_m).any()  # no setpoint
    goals.update(controller.snapshot(), time.monotonic())
    assert not goals.marker.visible

    controller.set_torque(True).result(timeout=WAIT_S)  # holds where the arm is: a goal again
    held = controller.snapshot().goal_m
    goals.update(controller.snapshot(), time.monotonic() + 10)  # past the drag's follow pause
    assert goals.marker.visible
    np.testing.assert_allclose(goals.marker.position, held, atol=1e-9)

"""The scene's goal handle with a wrist: its turn about z is the goal's phi (laws of
`yaw_of`, checked against scipy's rotations), a drag with a turned handle sends that phi and
the wrist turns to it, the heading arrow and the tool follow phi; without a wrist the
handle only translates and phi stays 0."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import numpy as np
import pytest
import viser
from fastapi.testclient import TestClient
from scipy.spatial.transform import Rotation

from app.scene.goal_view import about_z, yaw_of
from app.scene.robot_view import RobotView, heading_arrow
from kinematics import THESIS_DELTA, Tool
from tests.support.app_client import make_client
from tests.support.lease import take_lease
from tests.support.wait import WAIT_S, wait_for

WRIST = {"enabled": True, "min_angle_rad": -1.0, "max_angle_rad": 1.2}
OFFSET = [0.02, 0.0, -0.03]
TIP = np.array([0.0, 0.01, -0.26])


def wxyz(rotation: Rotation) -> np.ndarray:
    x, y, z, w = rotation.as_quat()
    return np.array([w, x, y, z])


@pytest.mark.parametrize("phi", [-3.0, -1.2, 0.0, 0.4, math.pi / 2, 2.9])
@pytest.mark.parametrize("tilt", [0.0, 0.3, -0.5])
def test_the_heading_of_a_turn_about_z_then_a_tilt_is_the_turn(phi: float, tilt: float) -> None:
    # R = Rz(phi) Rx(tilt) (intrinsic Z then X): the tilt leaves the x axis where Rz put it
    turned = Rotation.from_euler("ZX", [phi, tilt])
    assert yaw_of(wxyz(turned)) == pytest.approx(phi, abs=1e-12)
    assert yaw_of(about_z(phi)) == pytest.approx(phi, abs=1e-12)
    np.testing.assert_allclose(wxyz(Rotation.from_euler("z", phi)), about_z(phi), atol=1e-12)


def test_a_quarter_turn_by_hand() -> None:
    half = math.sqrt(0.5)
    assert yaw_of((half, 0.0, 0.0, half)) == pytest.approx(math.pi / 2)  # 90 deg about z
    assert yaw_of((half, half, 0.0, 0.0)) == pytest.approx(0.0)  # 90 deg about x: no heading


def test_the_heading_arrow_and_the_tool_turn_with_phi() -> None:
    arrow = heading_arrow([0.0, 0.0, -0.2], math.pi / 2, 0.03)
    np.testing.assert_allclose(arrow[0], [[0.0, 0.0, -0.2], [0.0, 0.03, -0.2]], atol=1e-12)
    joints = THESIS_DELTA.ik([0.01, 0.0, -0.22]).joints
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        view = RobotView(server, THESIS_DELTA, "/wristed", tool=Tool(offset_m=OFFSET, wrist=True))
        assert view.update(joints, math.pi / 2)
        segment = np.asarray(view.tool.points)[0]
        np.testing.assert_allclose(segment[1] - segment[0], [0.0, 0.02, -0.03], atol=1e-6)
        assert not view.update(joints, math.pi / 2)  # unchanged: nothing sent
        assert view.update(joints, 0.0)  # only phi changed: redrawn
        np.testing.assert_allclose(
            np.asarray(view.tool.points)[0, 1] - segment[0], OFFSET, atol=1e-6
        )
        view.remove()
    finally:
        server.stop()


@pytest.fixture(scope="module")
def wristed(tmp_path_factory) -> Iterator[TestClient]:
    folder = tmp_path_factory.mktemp("runs")
    settings = {"server": {"scene": True}, "wrist": WRIST, "tool": {"offset_m": OFFSET}}
    with make_client(folder, **settings) as client:
        take_lease(client)
        controller = client.app.state.controller
        controller.reset().result(timeout=WAIT_S)
        controller.set_torque(True).result(timeout=WAIT_S)
        yield client


@pytest.mark.slow
def test_a_turned_handle_sends_its_phi_and_the_wrist_turns(wristed: TestClient) -> None:
    scene, controller = wristed.app.state.scene, wristed.app.state.controller
    goals = scene.goals
    assert not goals.gizmo.disable_rotations
    turned = wxyz(Rotation.from_euler("ZX", [0.6, 0.2]))  # a heading of 0.6 rad, tilted
    sent = goals.drag_pose(TIP, turned, final=True)
    assert sent is not None, goals.message
    np.testing.assert_allclose(sent, TIP, atol=1e-12)
    wait_for(
        lambda: abs(controller.snapshot().phi_rad - 0.6) < 0.01,
        "the wrist at the handle's heading",
        seen=lambda: (controller.snapshot().phi_goal_rad, goals.message),
    )
    assert controller.snapshot().phi_goal_rad == pytest.approx(0.6)
    np.testing.assert_allclose(goals.gizmo.wxyz, about_z(0.6), atol=1e-12)  # tilt dropped
    # the drawn heading follows the measured wrist angle

    def heading() -> float:  # a frame drawn now (the display thread draws only for clients)
        scene.update(time.monotonic())
        ((dx, dy, _),) = np.diff(np.asarray(scene.robot.heading.points)[0], axis=0)
        return math.atan2(dy, dx)

    wait_for(lambda: abs(heading() - 0.6) < 0.01, "the heading arrow turned", seen=heading)
    # past the wrist's limit the handle asks for the limit
    assert goals.phi_of(about_z(2.0)) == pytest.approx(WRIST["max_angle_rad"])
    # a translation-only drag keeps the wrist where it was sent
    goals.drag_to(TIP + [0.01, 0.0, 0.0], final=True)
    assert controller.snapshot().phi_goal_rad == pytest.approx(0.6)


@pytest.mark.slow
def test_without_a_wrist_the_handle_only_translates(app_client: TestClient) -> None:
    scene, controller = app_client.app.state.scene, app_client.app.state.controller
    controller.reset().result(timeout=WAIT_S)
    controller.set_torque(True).result(timeout=WAIT_S)
    goals = scene.goals
    assert goals.gizmo.disable_rotations and goals.phi_of(about_z(0.6)) is None
    assert scene.robot.heading is None
    sent = goals.drag_pose([0.0, 0.0, -0.24], about_z(0.6), final=True)
    assert sent is not None, goals.message
    assert controller.snapshot().phi_rad == 0.0
    np.testing.assert_allclose(goals.gizmo.wxyz, (1.0, 0.0, 0.0, 0.0))

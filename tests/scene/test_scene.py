"""The scene against a running app: the drag path, panel commands, goal points, test runs.

Everything here goes through the same server-side methods viser's callbacks call (the
gizmo's ``on_update`` calls ``GoalView.drag_to``; buttons call the panel's methods).
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
import pytest
import viser

from app.scene.geometry import robot_lines
from app.scene.goal_view import INSIDE_COLOUR, PROJECTED_COLOUR
from app.scene.run_panel import RunPanel
from tests.support.app_client import wait_at
from tests.support.wait import WAIT_S, ok_json, wait_for


def _goal(scene) -> np.ndarray:
    return scene.controller.snapshot().goal_m


@pytest.mark.slow
def test_info_names_the_port_the_scene_is_bound_to(scene, app_client):
    """The config asks for port 0 (a free one): /api/info names the one viser got."""
    assert ok_json(app_client.get("/api/info"))["viser_port"] == scene.server.get_port() > 0


@pytest.mark.slow
def test_drag_inside_sends_every_update_as_the_goal(scene, app_client):
    for point in ([0.01, 0.0, -0.24], [0.02, 0.01, -0.25], [0.03, -0.01, -0.26]):
        sent = scene.goals.drag_to(np.array(point))  # mid-drag updates, not only the end
        np.testing.assert_allclose(sent, point)
        wait_for(lambda p=point: np.allclose(_goal(scene), p), f"goal {point}")
    assert tuple(scene.goals.marker.color) == INSIDE_COLOUR
    wait_at(app_client, [0.03, -0.01, -0.26], "the robot at the dragged goal")


def test_drag_outside_is_projected_and_the_gizmo_snaps_back(scene):
    outside = np.array([0.6, 0.1, -0.2])
    sent = scene.goals.drag_to(outside, final=True)
    gate = scene.controller.gate
    assert gate.inside(sent)
    # The workspace projection, or (past a joint limit there) the furthest good point
    # towards it: never closer to the dragged point than the projection itself.
    nearest = gate.nearest(outside)
    assert np.linalg.norm(sent - outside) >= np.linalg.norm(nearest - outside) - 1e-9
    np.testing.assert_allclose(scene.goals.gizmo.position, sent)  # snapped back
    assert tuple(scene.goals.marker.color) == PROJECTED_COLOUR
    wait_for(lambda: np.allclose(_goal(scene), sent), "the projected goal in the loop")


def test_drag_with_torque_off_says_why(scene):
    scene.controller.set_torque(False).result(timeout=WAIT_S)
    scene.goals.drag_to(np.array([0.0, 0.0, -0.25]), final=True)
    wait_for(lambda: "torque is off" in scene.goals.message, "the refusal message")
    scene.panel.update(scene.controller.snapshot())
    assert "torque is off" in scene.panel.gui_status.content


@pytest.mark.slow
def test_frame_draws_the_measured_pose(scene, app_client):
    scene.goals.drag_to(np.array([0.04, 0.02, -0.22]), final=True)
    wait_at(app_client, [0.04, 0.02, -0.22], "the robot at the goal")
    scene.update(time.monotonic())
    drawn_joints = scene.robot._joints
    expected = robot_lines(scene.controller.robot, drawn_joints)
    np.testing.assert_allclose(scene.robot.upper.points, expected.upper, atol=1e-6)
    np.testing.assert_allclose(scene.robot.rods.points, expected.rods.reshape(6, 2, 3), atol=1e-6)
    np.testing.assert_allclose(scene.robot.platform.position, [0.04, 0.02, -0.22], atol=3e-3)


def test_jog_step_moves_the_goal_by_the_step(scene):
    scene.goals.drag_to(np.array([0.0, 0.0, -0.25]), final=True)
    wait_for(lambda: np.allclose(_goal(scene), [0.0, 0.0, -0.25]), "the start goal")
    scene.panel.jog((0, 0, -1), step_mm=10.0)
    wait_for(lambda: np.allclose(_goal(scene), [0.0, 0.0, -0.26], atol=1e-9), "the jog goal")
    assert scene.panel.message == ""


def test_estop_and_reset_buttons(scene):
    scene.panel._call(scene.controller.estop)
    wait_for(lambda: scene.controller.snapshot().mode == "estop", "e-stop")
    scene.goals.drag_to(np.array([0.0, 0.0, -0.25]), final=True)
    wait_for(lambda: "e-stop" in scene.goals.message, "motion refused under e-stop")
    scene.panel._call(scene.controller.reset)
    wait_for(lambda: scene.controller.snapshot().mode != "estop", "reset")


@pytest.mark.slow
def test_goal_points_save_go_to_delete(scene, app_client):
    scene.goals.drag_to(np.array([-0.03, 0.02, -0.27]), final=True)
    wait_for(lambda: np.allclose(_goal(scene), [-0.03, 0.02, -0.27]), "the goal")
    assert scene.panel.save_point("pick") == "pick"
    assert "pick" in scene.goals.saved and "pick" in scene.panel.point_names()
    scene.goals.drag_to(np.array([0.03, 0.0, -0.22]), final=True)
    scene.panel.go_to("pick")
    wait_at(app_client, [-0.03, 0.02, -0.27], "the robot at the saved point")
    scene.panel.delete_point("pick")
    assert "pick" not in scene.goals.saved
    assert scene.panel.point_names() == ()


def test_sinusoid_fields_in_ui_units_give_the_thesis_test(scene):
    """A client's fields as they open (mm, Hz, deg, s) are the thesis test in SI."""
    from app.runs.trajectories import SinusoidParams

    shown = {
        "amplitude": (50.0, 50.0, 80.0),
        "frequency": (1.0, 1.0, 2.0),
        "phase": (0.0, 0.0, 0.0),
        "offset": (0.0, 0.0, -240.0),
        "duration": 10.0,
        "feedforward": False,
    }
    params, default = scene.tests.params(shown), SinusoidParams()
    for name in ("amplitude_m", "frequency_hz", "phase_rad", "offset_m"):
        np.testing.assert_allclose(getattr(params, name), getattr(default, name), atol=1e-12)
    assert (params.duration_s, params.feedforward) == (default.duration_s, default.feedforward)


def test_sinusoid_preview_start_and_abort(scene):
    scene.goals.drag_to(np.array([0.0, 0.0, -0.24]), final=True)
    # A plan is made from where the robot is: let it arrive before starting.
    commanded = lambda: scene.controller.snapshot().point_commanded_m  # noqa: E731
    wait_for(lambda: np.allclose(commanded(), [0.0, 0.0, -0.24], atol=1e-4), "the robot there")
    scene.tests.preview()
    assert scene.goals.path.visible
    path = np.asarray(scene.goals.path.points)
    assert np.ptp(path[:, 0, 2]) > 0.15  # the 80 mm z amplitude, peak to peak
    scene.tests.start()
    assert scene.tests.message.startswith("running"), scene.tests.message
    run_id = scene.tests.run_id
    runs = scene.runs()
    assert runs.get(run_id).state == "running"
    scene.tests.abort()
    wait_for(lambda: runs.get(run_id).state == "aborted", "the run aborted")
    scene.tests.update(time.monotonic())
    assert run_id in scene.tests.gui_result.content


def test_run_panel_without_runs_says_so(monkeypatch):
    monkeypatch.setitem(sys.modules, "app.runs.trajectories", None)  # import fails
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        panel = RunPanel(server, lambda: None, lambda path: None)
        assert "not available" in panel.gui_unavailable.content
        panel.start()
        assert "not available" in panel.message
    finally:
        server.stop()


@pytest.mark.slow
def test_tracking_error_plot_keeps_the_window(scene):
    now = time.monotonic()
    for k in range(5):
        scene.tests.record(scene.controller.snapshot(), now + 3.0 * k)
    scene.tests.update(now + 12.0)
    times = scene.tests.gui_plot.data[0]
    assert len(times) >= 2 and times.min() >= -10.0 - 1e-9 and math.isclose(times.max(), 0.0)


@pytest.mark.slow  # a second app and scene
def test_a_linear_delta_draws_as_one():
    from app.scene.robot_view import RobotView
    from app.scene.workspace_view import WorkspaceView
    from kinematics import LinearDelta

    robot = LinearDelta(l=0.25, R=0.15, r=0.04)
    joints, ok = robot.ik([0.02, -0.01, -0.2])
    assert ok
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        view = RobotView(server, robot, "/linear")
        assert view.update(joints)
        expected = robot_lines(robot, joints)
        np.testing.assert_allclose(view.upper.points, expected.upper, atol=1e-6)
        np.testing.assert_allclose(view.platform.position, [0.02, -0.01, -0.2], atol=1e-9)
        workspace = WorkspaceView(server, robot, margin_m=0.002, z_max_m=-0.06)
        assert len(workspace.mesh.faces) > 100 and len(workspace.tori) == 3
        view.remove()
        workspace.remove()
    finally:
        server.stop()

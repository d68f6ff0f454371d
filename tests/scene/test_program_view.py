"""The checked program in the scene: a check's report draws its path and its violations in
red (app/scene/program_view.py), and POST /api/programs/check publishes each report there."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import viser

from app.scene.program_view import RUNNING_COLOUR, VIOLATION_COLOUR, ProgramView

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture
def server() -> Iterator[viser.ViserServer]:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        yield server
    finally:
        server.stop()


def nodes(server: viser.ViserServer) -> set[str]:
    """The node names the viser server holds (and sends to every client)."""
    return set(server.scene._handle_from_node_name)


def test_a_report_draws_its_path_and_red_violation_points(server):
    view = ProgramView(server)
    path = [[0.0, 0.0, -0.24], [0.03, 0.0, -0.24], [0.03, 0.0, -0.1], [0.03, 0.01, -0.05]]
    report = {
        "path_m": path,
        "violations": [
            {"line": 5, "kind": "ceiling", "point_m": [0.03, 0.0, -0.055]},
            {"line": 6, "kind": "ik", "point_m": [0.03, 0.0, -0.0551]},
        ],
    }
    view.show_report(report)
    assert {"/program/path", "/program/violations"} <= nodes(server)
    segments = view.path.points
    assert segments.shape == (3, 2, 3)  # consecutive points joined, none skipped
    np.testing.assert_allclose(segments[:, 0], path[:-1], atol=1e-6)
    np.testing.assert_allclose(segments[:, 1], path[1:], atol=1e-6)
    np.testing.assert_allclose(
        view.violations.points, [v["point_m"] for v in report["violations"]], atol=1e-7
    )
    assert tuple(np.asarray(view.violations.colors).reshape(-1, 3)[0]) == VIOLATION_COLOUR

    view.show_report({"path_m": path[:2], "violations": []})  # a passing check: no red left
    assert "/program/violations" not in nodes(server) and view.violations is None
    assert view.path.points.shape == (1, 2, 3)

    view.visible = False
    assert not view.path.visible
    view.show_report(report)  # hidden by the operator's toggle: stays hidden when redrawn
    assert not view.path.visible and not view.violations.visible

    view.show_report(None)  # a program that cannot be read: nothing drawn
    assert not {"/program/path", "/program/violations"} & nodes(server)


def test_non_finite_points_are_dropped_not_sent(server):
    view = ProgramView(server)
    view.show([[0, 0, -0.2], [np.nan, 0, -0.2], [0.01, 0, -0.2]], [[np.inf, 0, 0]])
    assert view.path.points.shape == (1, 2, 3)
    assert view.violations is None


@pytest.mark.slow
def test_the_check_route_publishes_its_report_to_the_scene(app_client, scene):
    text = (EXAMPLES / "fails.ngc").read_text()
    response = app_client.post(
        "/api/programs/check", json={"gcode": text, "start_m": [0.0, 0.0, -0.24]}
    )
    assert response.status_code == 200, response.text
    report = response.json()
    assert not report["ok"] and report["violations"]
    drawn = scene.program
    np.testing.assert_allclose(drawn.path.points[:, 0], report["path_m"][:-1], atol=1e-6)
    np.testing.assert_allclose(drawn.path.points[-1, 1], report["path_m"][-1], atol=1e-6)
    expected = [v["point_m"] for v in report["violations"]]
    np.testing.assert_allclose(drawn.violations.points, expected, atol=1e-6)

    unreadable = app_client.post("/api/programs/check", json={"gcode": "G1 X1 Q5"})
    assert unreadable.status_code == 422
    assert scene.program.path is not None  # a program that cannot be read changes nothing


def test_the_running_line_is_drawn_over_its_part_of_the_path(server):
    view = ProgramView(server)
    path = [[0.01 * i, 0.0, -0.24] for i in range(8)]
    lines = [None, 3, 3, 4, 4, 4, 6, 6]  # path_lines: the line of each point
    view.show_report({"path_m": path, "path_lines": lines, "violations": []})
    assert "/program/running" not in nodes(server)
    view.show_line(4)
    segments = view.running.points
    # line 4's points (3..5) and one point either side: the part joins the path around it
    np.testing.assert_allclose(segments[:, 0], path[2:6], atol=1e-6)
    np.testing.assert_allclose(segments[:, 1], path[3:7], atol=1e-6)
    assert tuple(np.asarray(view.running.colors).reshape(-1, 3)[0]) == RUNNING_COLOUR
    view.show_line(6)  # the next line: the last one's highlight goes
    np.testing.assert_allclose(view.running.points[:, 0], path[5:7], atol=1e-6)
    view.show_line(5)  # a line with no drawn point (e.g. a dwell): nothing highlighted
    assert view.running is None and "/program/running" not in nodes(server)
    view.show_line(3)
    view.show_line(None)  # the run ended
    assert "/program/running" not in nodes(server)
    view.show_line(3)
    view.show_report({"path_m": path[:2], "violations": []})  # a new check: no old highlight
    assert view.running is None and view.running_line is None

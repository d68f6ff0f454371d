"""Saved goal points outlive a restart: the JSON store, and a second server reading it."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.scene.goal_store import FILE_NAME, load_points, save_points
from tests.support.app_client import make_client


def test_points_round_trip_exactly_and_leave_no_temporary_file(tmp_path):
    path = tmp_path / "deep" / FILE_NAME
    points = {"pick": np.array([0.01, -0.02, -0.25]), "place é": np.array([0.1 / 3, 0.0, -0.2])}
    save_points(path, points)
    loaded = load_points(path)
    assert list(loaded) == list(points)  # the operator's order is kept
    for name, point in points.items():
        assert np.array_equal(loaded[name], point)  # bit for bit through JSON
    assert sorted(p.name for p in path.parent.iterdir()) == [FILE_NAME]


def test_a_damaged_file_is_skipped_with_a_warning_not_a_crash(tmp_path, caplog):
    path = tmp_path / FILE_NAME
    assert load_points(path) == {}  # no file yet
    path.write_text("{not json")
    with caplog.at_level(logging.WARNING):
        assert load_points(path) == {}
    assert "cannot read" in caplog.text
    good = [0.0, 0.0, -0.25]
    bad = {"nan": [float("nan"), 0, 0], "short": [0, 0], "text": ["a", 0, 0], "flag": [True, 0, 0]}
    path.write_text(json.dumps({"points": {"good": good, **bad}}))  # Python writes NaN there
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        loaded = load_points(path)
    assert list(loaded) == ["good"]
    for name in bad:
        assert f"{name}:" in caplog.text


def _scene_app(folder) -> TestClient:
    return make_client(folder, server={"scene": True})


@pytest.mark.slow
def test_points_saved_in_the_scene_are_there_after_a_restart(tmp_path):
    with _scene_app(tmp_path) as client:
        scene = client.app.state.scene
        scene.goals.save("pick", np.array([-0.03, 0.02, -0.27]))
        scene.panel._refresh_points()
        scene.goals.save("gone", np.array([0.0, 0.0, -0.22]))
        scene.goals.delete("gone")
    with _scene_app(tmp_path) as client:
        scene = client.app.state.scene
        assert list(scene.goals.saved) == ["pick"]
        np.testing.assert_array_equal(scene.goals.saved["pick"], [-0.03, 0.02, -0.27])
        assert scene.panel.point_names() == ("pick",)
        assert scene.panel.next_point_name() == "point 2"

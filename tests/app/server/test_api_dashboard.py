"""The API the dashboard adds: /api/info, the sinusoid preview and the vendored plotly.js."""

from __future__ import annotations

from collections.abc import Iterator
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import load_settings
from app.control.commands import CommandContext
from app.runs.trajectories import SinusoidParams
from app.server.api.dashboard import peak_joint_speed
from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for


def hold_at_centre(client: TestClient) -> None:
    """Torque on and the platform at the thesis sinusoid's centre, (0, 0, -0.24) m."""
    client.post("/api/reset")
    torque_on(client)
    client.post("/api/goal", json={"position_m": [0.0, 0.0, -0.24]})
    wait_for(
        lambda: abs(ok_json(client.get("/api/status"))["ee"]["position_m"][2] + 0.24) < 0.003,
        "arrival at the sinusoid's centre",
    )


@pytest.fixture(scope="module")
def client(tmp_path_factory) -> Iterator[TestClient]:
    # the default backend, the simulator: no pty, no emulator process
    with make_client(tmp_path_factory.mktemp("runs"), backend="sim") as test_client:
        take_lease(test_client)
        hold_at_centre(test_client)
        yield test_client


@pytest.mark.slow
def test_info_says_no_scene_and_no_token(client: TestClient) -> None:
    """This app has no 3D scene (tests/scene/ checks the port /api/info names when on)."""
    info = ok_json(client.get("/api/info"))
    settings = client.app.state.settings
    assert client.app.state.scene is None and info["viser_port"] is None
    assert info["token_required"] is False
    assert info["jog_step_m"] == settings.jog.step_m


def test_check_of_thesis_sinusoid_is_feasible_and_reports_joint_speed(client: TestClient) -> None:
    body = ok_json(client.post("/api/tests/sinusoid/check", json={"duration_s": 2}))
    assert body["feasible"] is True, body["detail"]
    assert 0 < body["peak_joint_speed_rad_s"] <= body["joint_speed_limit_rad_s"]
    # thesis Z axis: 8 cm at 2 Hz -> 2 pi 2 0.08 ~ 1.005 m/s is the fastest axis
    assert body["peak_speed_m_s"] == pytest.approx(2 * 3.141592653589793 * 2 * 0.08)


def test_check_names_the_infeasible_time_and_starts_nothing(client: TestClient) -> None:
    runs_before = len(ok_json(client.get("/api/runs")))
    body = client.post(
        "/api/tests/sinusoid/check", json={"amplitude_m": [0.3, 0, 0], "duration_s": 2}
    ).json()
    assert body["feasible"] is False
    assert "infeasible" in body["detail"] and "t = " in body["detail"]
    assert len(ok_json(client.get("/api/runs"))) == runs_before
    assert ok_json(client.get("/api/status"))["mode"] != "test"


def test_peak_joint_speed_does_not_depend_on_where_the_arm_hangs() -> None:
    """A relaxed arm hanging nearly straight down (1.55 rad) must not change the preview:
    IK near those joints picked other branches for some samples (jumps of ~650 rad/s)."""
    ctx = CommandContext.from_settings(load_settings())
    params = SinusoidParams(duration_s=2.0)

    def controller(joints_rad: float) -> Any:
        snapshot = SimpleNamespace(joints_measured_rad=np.full(3, joints_rad))
        return SimpleNamespace(
            period_s=0.005, robot=ctx.robot, gate=ctx.gate, snapshot=lambda: snapshot
        )

    hanging, held = (peak_joint_speed(controller(j), params) for j in (1.55, 0.3))
    assert hanging == pytest.approx(held)
    assert 1.0 < held < 10.0  # the thesis test drives the XM430s near their 7.5 rad/s limit


def test_faster_sinusoid_previews_a_higher_joint_speed(client: TestClient) -> None:
    def peak(frequency_hz: float) -> float:
        body = {"frequency_hz": [frequency_hz, 0, 0], "amplitude_m": [0.02, 0, 0], "duration_s": 2}
        checked = ok_json(client.post("/api/tests/sinusoid/check", json=body))
        return checked["peak_joint_speed_rad_s"]

    assert peak(1.0) > peak(0.5) > 0


def test_check_rejects_bad_input_with_422(client: TestClient) -> None:
    response = client.post("/api/tests/sinusoid/check", json={"duration_s": -1})
    assert response.status_code == 422
    assert "duration_s" in response.json()["detail"]


@pytest.mark.slow
def test_plotly_is_served_from_the_installed_package(client: TestClient) -> None:
    response = client.get("/vendor/plotly.min.js")
    assert response.status_code == 200
    assert "javascript" in response.headers["content-type"]
    assert b"plotly.js" in response.content[:200]


@pytest.mark.slow
def test_with_a_token_info_says_so_and_the_check_needs_it(tmp_path) -> None:
    token = "a-long-secret-1"
    with make_client(tmp_path, server={"token": token}) as client:  # emulated: starts faster
        assert ok_json(client.get("/api/info"))["token_required"] is True
        url = "/api/tests/sinusoid/check"
        assert client.post(url, json={"duration_s": 1}).status_code == 401
        headers = {"Authorization": f"Bearer {token}"}
        assert client.post(url, json={"duration_s": 1}, headers=headers).status_code == 200


def test_info_names_the_long_move_distance_and_a_reachable_home(client: TestClient) -> None:
    info = ok_json(client.get("/api/info"))
    settings = client.app.state.settings
    assert info["confirm_move_m"] == settings.jog.confirm_move_m == 0.05
    assert info["home_m"] == list(settings.jog.home_m)
    _, ok = settings.robot.build().ik(np.array(info["home_m"]))
    assert bool(ok), "the dashboard's home point must be reachable"


@pytest.mark.slow
def test_check_of_a_relaxed_arm_starts_from_where_it_hangs(client: TestClient) -> None:
    """Torque off: the command is the last held point, the arm falls from it; the preview's
    "the robot is there now" must name the measured point, not the old command."""
    hold_at_centre(client)
    held = np.array(ok_json(client.get("/api/status"))["ee"]["commanded_m"])
    ok_json(client.post("/api/torque", json={"enabled": False}))

    def names_the_measured_point() -> bool:
        detail = client.post("/api/tests/sinusoid/check", json={"duration_s": 2}).json()["detail"]
        if not detail or "there now" not in detail:
            return False
        named = np.array([float(v) for v in detail.split("point [")[1].split("]")[0].split(",")])
        measured = np.array(ok_json(client.get("/api/status"))["ee"]["position_m"])
        return bool(
            np.linalg.norm(named - measured) < 0.005 and np.linalg.norm(named - held) > 0.02
        )

    try:
        wait_for(names_the_measured_point, "the check to start from the hanging arm")
    finally:
        hold_at_centre(client)

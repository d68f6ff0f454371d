"""Test runs with the wrist as a fourth axis (issue 19): the sinusoid's and the step's phi,
refused without a wrist, logged and followed on the twin with one."""

from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest

from app.runs.paths import StepParams
from app.runs.source import TrajectorySource
from app.runs.trajectories import SinusoidParams, plan_sinusoid
from tests.support.app_client import make_client, settle_at
from tests.support.lease import take_lease
from tests.support.wait import ok_json, wait_for

WRIST = {"enabled": True, "min_angle_rad": -1.5, "max_angle_rad": 1.5}
SMALL = {"amplitude_m": [0.01, 0.01, 0.01], "frequency_hz": [0.5, 0.5, 0.5], "duration_s": 2.0}


def test_phi_of_the_sinusoid_and_the_step():
    sine = SinusoidParams(phi_amplitude_rad=0.4, phi_frequency_hz=0.5)
    t = np.linspace(0.0, 3.0, 301)
    np.testing.assert_allclose(sine.phi_at(t), 0.4 * np.sin(math.pi * t), atol=1e-15)
    # the peak speed is the largest finite-difference slope
    slope = np.max(np.abs(np.diff(sine.phi_at(t)) / np.diff(t)))
    assert sine.phi_peak_speed() == pytest.approx(slope, rel=1e-3)
    step = StepParams(step_at_s=0.5, phi_step_rad=-0.3)
    assert step.phi_at(np.array([0.0, 0.49, 0.5, 1.9])).tolist() == [0.0, 0.0, -0.3, -0.3]
    assert not SinusoidParams().moves_wrist and not StepParams().moves_wrist


def test_a_run_without_phi_leaves_the_wrist_alone_and_one_with_phi_commands_it():
    start = np.array([0.0, 0.0, -0.24])
    plain = TrajectorySource(plan_sinusoid(SinusoidParams(duration_s=1.0), start))
    assert all(plain.next(0.005).phi_rad is None for _ in range(400))
    params = SinusoidParams(duration_s=1.0, phi_amplitude_rad=0.4, phi_frequency_hz=1.0)
    plan = plan_sinusoid(params, start)
    turning = TrajectorySource(plan)
    for _ in range(400):
        setpoint = turning.next(0.005)
        timed = min(max(turning.t_s - plan.approach_s, 0.0), params.duration_s)
        assert setpoint.phi_rad == pytest.approx(float(params.phi_at(np.array(timed))))


@pytest.mark.slow
def test_phi_without_a_wrist_is_refused_naming_the_field(tmp_path):
    with make_client(tmp_path) as client:
        take_lease(client)
        client.post("/api/torque", json={"enabled": True})
        body = {**SMALL, "phi_amplitude_rad": 0.3, "phi_frequency_hz": 0.5}
        response = client.post("/api/tests/sinusoid", json=body)
        assert response.status_code == 422, response.text
        assert "phi_amplitude_rad" in response.text and "wrist" in response.text
        response = client.post("/api/tests/step", json={"phi_step_rad": 0.2})
        assert response.status_code == 422, response.text
        assert "phi_step_rad" in response.text
        assert ok_json(client.get("/api/runs")) == []  # nothing started


@pytest.mark.slow  # an end-to-end run of seconds on the twin
def test_a_sinusoid_with_phi_on_the_twin_logs_the_wrist_following_its_goal(tmp_path):
    # a loaded machine stalls the simulator for tenths of a second: the test checks the
    # wrist's run, not the stale-feedback guard (tests/runs/test_run_health.py has that)
    safety = {"stale_feedback_s": 5.0}
    sections = {"wrist": WRIST, "tool": {"offset_m": [0.0, 0.0, -0.05]}, "safety": safety}
    with make_client(tmp_path, "sim", **sections) as client:
        take_lease(client)
        settle_at(client, [0.0, 0.0, -0.29])  # a run refuses to start from a moving arm
        too_far = {**SMALL, "offset_m": [0, 0, -0.29], "phi_amplitude_rad": 2.0}
        response = client.post("/api/tests/sinusoid", json={**too_far, "phi_frequency_hz": 0.1})
        assert response.status_code == 422 and "phi_amplitude_rad" in response.text
        body = {**SMALL, "offset_m": [0, 0, -0.29], "phi_amplitude_rad": 0.5}
        response = client.post("/api/tests/sinusoid", json={**body, "phi_frequency_hz": 0.5})
        assert response.status_code == 200, response.text
        run_id = response.json()["run_id"]
        wait_for(
            lambda: ok_json(client.get(f"/api/runs/{run_id}"))["state"] != "running", "the run"
        )
        run = ok_json(client.get(f"/api/runs/{run_id}"))
        assert run["state"] == "done", run
        text = client.get(f"/api/runs/{run_id}/log.csv").text
    rows = [r for r in csv.DictReader(io.StringIO(text)) if r["phase"] == "timed"]
    goal = np.array([float(r["phi_goal_rad"]) for r in rows])
    measured = np.array([float(r["phi_measured_rad"]) for r in rows])
    commanded = np.array([float(r["phi_commanded_rad"]) for r in rows])
    # the simulator's time: what the servo lived through (a loaded machine stalls the
    # simulator between ticks; the wall-clock lag then says nothing of the servo)
    times = np.array([float(r["sim_time_s"]) for r in rows])
    keep = np.concatenate([[True], np.diff(times) > 0])  # a stale read repeats a state
    times, goal, measured, commanded = times[keep], goal[keep], measured[keep], commanded[keep]
    assert np.ptp(goal) > 0.9  # the goal swept most of +-0.5 rad
    # the wrist followed its goal, lagging (servo and simulator, more on a loaded machine):
    # the goal delayed by the best lag up to 0.5 s fits the reading to a small residual
    lags = np.arange(0.0, 0.5, 0.005)
    residual = [
        np.sqrt(np.mean((np.interp(times - lag, times, goal) - measured) ** 2)) for lag in lags
    ]
    assert min(residual) < 0.1 * np.ptp(goal), (lags[int(np.argmin(residual))], min(residual))
    assert min(residual) < 0.5 * residual[-1]  # and the fit is no accident of any lag
    assert np.ptp(measured) > 0.8 * np.ptp(goal)
    # the command went out with the goal (late ticks may hold it a few ticks behind)
    assert np.sqrt(np.mean((commanded - goal) ** 2)) < 0.1 * np.ptp(goal)
    assert run["stats"]["wrist"]["samples"] > 0
    assert run["stats"]["wrist"]["rmse_rad"] == pytest.approx(
        np.sqrt(np.mean((goal - measured) ** 2)), rel=0.5
    )

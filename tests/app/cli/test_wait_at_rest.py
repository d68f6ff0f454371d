"""Issue 28 point 4: ``deltadash run sinusoid`` planned right after torque on, while the
arm still settled, and on a loaded machine the loop refused the run ("the robot moved
13.3 mm since the plan") in 6 of 6 tries. The command now waits for the arm to stand
still, in loop time, with a deadline. Here a scripted loop plays the arm's motion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from app.cli.run import wait_at_rest
from app.control.errors import MotionRefused


@dataclass
class Snap:
    time_s: float
    point_measured_m: np.ndarray
    mode: str = "hold"


class ScriptedLoop:
    """Each snapshot is the next 5 ms tick of ``path(t)``; a clock that reads 1 ms of wall
    time per call (fast or slow, the answer must not depend on it)."""

    def __init__(self, path, mode_at=lambda t: "hold") -> None:
        self.path, self.mode_at, self.t, self.wall = path, mode_at, 0.0, 0.0

    def snapshot(self) -> Snap:
        self.t += 0.005
        return Snap(self.t, np.asarray(self.path(self.t), dtype=float), self.mode_at(self.t))

    def clock(self) -> float:
        self.wall += 0.001
        return self.wall


def settling(t: float) -> np.ndarray:
    """Falls 13 mm at 13 mm/s, then stands still at z = -0.253 m from t = 1 s."""
    return np.array([0.0, 0.0, -0.24 - 0.013 * min(t, 1.0)])


def test_it_returns_only_once_the_arm_has_stood_still_for_the_window(monkeypatch):
    monkeypatch.setattr("app.cli.run.time.sleep", lambda s: None)
    loop = ScriptedLoop(settling)
    point = wait_at_rest(loop, window_s=0.3, tol_m=2e-4, deadline_s=60, clock=loop.clock)
    np.testing.assert_allclose(point, [0.0, 0.0, -0.253])
    # within 0.2 mm of where it stops from t = 1 - 0.2 / 13 s: at rest 0.3 s of loop time
    # later, not before
    assert 1.0 - 0.2 / 13 + 0.3 - 1e-9 <= loop.t <= 1.3 + 0.01


def test_a_slow_creep_under_the_tolerance_counts_as_rest(monkeypatch):
    monkeypatch.setattr("app.cli.run.time.sleep", lambda s: None)
    creep = ScriptedLoop(lambda t: [0.0, 0.0, -0.24 - 1e-4 * t])  # 0.1 mm/s
    wait_at_rest(creep, window_s=0.3, tol_m=2e-4, deadline_s=60, clock=creep.clock)
    assert creep.t <= 0.3 + 0.02


@pytest.mark.slow
def test_an_arm_that_never_settles_is_refused_at_the_deadline(monkeypatch):
    monkeypatch.setattr("app.cli.run.time.sleep", lambda s: None)
    swinging = ScriptedLoop(lambda t: [0.01 * np.sin(2 * np.pi * t), 0.0, -0.24])
    with pytest.raises(MotionRefused, match=r"did not come to rest within 2 s.*moved [0-9.]+ mm"):
        wait_at_rest(swinging, window_s=0.3, tol_m=2e-4, deadline_s=2, clock=swinging.clock)
    assert swinging.wall == pytest.approx(2.0, abs=0.01)


def test_a_fault_while_waiting_is_said_at_once(monkeypatch):
    monkeypatch.setattr("app.cli.run.time.sleep", lambda s: None)
    faulting = ScriptedLoop(settling, mode_at=lambda t: "fault" if t > 0.5 else "hold")
    with pytest.raises(MotionRefused, match="fault"):
        wait_at_rest(faulting, deadline_s=60, clock=faulting.clock)
    assert faulting.t < 0.51


@pytest.mark.slow
def test_the_headless_run_waits_for_rest_before_it_plans(monkeypatch):
    """The order the issue asks for: torque on, at rest, then the plan."""
    import app.cli.run as run

    calls: list[str] = []
    monkeypatch.setattr(run, "wait_at_rest", lambda controller: calls.append("rest"))

    class Manager:
        def __init__(self, *args) -> None:
            pass

        def start_sinusoid(self, params):
            calls.append("plan")
            raise MotionRefused("stop here")

    monkeypatch.setattr("app.runs.manager.RunManager", Manager)
    with pytest.raises(MotionRefused, match="stop here"):
        run._headless(run.SinusoidParams(duration_s=1.0), "emulated")
    assert calls == ["rest", "plan"]

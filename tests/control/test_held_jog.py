"""Hold-to-move in the tick: a controller stepped by hand on a fake clock and a fake bus.

The law: a held jog moves while heartbeats come; once none has come for longer than
``jog.hold_timeout_s`` the jog's target is frozen and the robot decelerates to a stop,
jerk-limited (it neither stops dead in one tick nor runs on to where it was heading).
"""

from __future__ import annotations

import numpy as np
import pytest

from app.config import load_settings
from app.control import commands, held_jog
from app.control.controller import Controller
from app.control.errors import MotionRefused
from app.control.sources import JogSource
from tests.support.fake_bus import HOME_M, FakeBus

SETTINGS = load_settings()
TIMEOUT_S = SETTINGS.jog.hold_timeout_s
SPEED_M_S = 0.05


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def held(velocity=(SPEED_M_S, 0.0, 0.0)) -> tuple[Controller, FakeClock, FakeBus]:
    """A controller with torque on at HOME and a held jog started at loop time 0."""
    clock, bus = FakeClock(), FakeBus()
    loop = Controller(SETTINGS, bus, "fake", clock=clock)
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    held_jog.hold_jog(loop.state, loop.ctx, np.array(velocity), loop._now())
    return loop, clock, bus


def tick(loop: Controller, clock: FakeClock, n: int = 1) -> np.ndarray:
    for _ in range(n):
        clock.now += loop.period_s
        loop.step()
    return loop.snapshot().point_commanded_m.copy()


def heartbeat(loop: Controller, velocity=(SPEED_M_S, 0.0, 0.0)) -> None:
    held_jog.hold_jog(loop.state, loop.ctx, np.array(velocity), loop._now())


def test_heartbeats_keep_it_moving_at_the_asked_speed() -> None:
    loop, clock, _ = held()
    for _ in range(20):  # 1 s of heartbeats every 50 ms
        tick(loop, clock, 10)
        heartbeat(loop)
    a = tick(loop, clock)
    b = tick(loop, clock)
    speed = np.linalg.norm(b - a) / loop.period_s
    assert speed == pytest.approx(SPEED_M_S, rel=0.02)
    assert abs(b[1] - HOME_M[1]) < 1e-9 and abs(b[2] - HOME_M[2]) < 1e-9  # along +x only
    assert loop.snapshot().mode == "jog" and loop.state.hold_deadline_s is not None


def test_no_heartbeat_for_the_timeout_freezes_the_target_and_decelerates_to_a_stop() -> None:
    loop, clock, _ = held()
    for _ in range(10):
        tick(loop, clock, 10)
        heartbeat(loop)
    last_heartbeat_s = loop._now()
    points, times = [], []
    while loop._now() - last_heartbeat_s < TIMEOUT_S + 1.0:
        points.append(tick(loop, clock))
        times.append(loop._now() - last_heartbeat_s)
    points, times = np.array(points), np.array(times)
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    speed = steps / loop.period_s
    before = times[1:] <= TIMEOUT_S
    assert speed[before].min() == pytest.approx(SPEED_M_S, rel=0.02)  # still moving until then
    stopped = np.flatnonzero(steps < 1e-9)
    assert stopped.size, "the jog never stopped"
    stop_s = times[1:][stopped[0]]
    assert stop_s > TIMEOUT_S  # not before the deadline
    assert np.all(steps[stopped[0] :] < 1e-9)  # and it stays stopped
    decelerating = speed[(times[1:] > TIMEOUT_S) & (times[1:] < stop_s)]
    assert decelerating.size >= 3 and np.all(np.diff(decelerating) <= 1e-9)  # smooth, not dead
    source = loop.state.source
    assert isinstance(source, JogSource) and not source.braking
    np.testing.assert_allclose(source.target_m, points[-1], atol=1e-9)  # target frozen there
    np.testing.assert_allclose(loop.snapshot().goal_m, points[-1], atol=1e-9)
    assert "no heartbeat" in loop.snapshot().notice
    print(f"stopped {stop_s * 1e3:.0f} ms after the last heartbeat (fake clock, 200 Hz)")


def test_the_first_hold_after_torque_on_says_so_while_held() -> None:
    loop, clock, _ = held()
    for _ in range(5):
        tick(loop, clock, 10)
        heartbeat(loop)
    assert loop.snapshot().notice == "starting from the measured position"


def test_a_zero_velocity_brakes_at_once() -> None:
    loop, clock, _ = held()
    tick(loop, clock, 20)
    heartbeat(loop, (0.0, 0.0, 0.0))
    assert loop.state.hold_deadline_s is None
    points = [tick(loop, clock) for _ in range(40)]
    assert np.linalg.norm(points[-1] - points[-2]) < 1e-9
    assert np.linalg.norm(points[-1] - points[0]) < 0.002  # braked where it was


def test_a_discrete_step_or_a_stop_ends_the_hold() -> None:
    loop, clock, bus = held()
    tick(loop, clock, 5)
    commands.jog_by(loop.state, loop.ctx, np.array([0.0, 0.0, 0.005]))
    assert loop.state.hold_deadline_s is None
    heartbeat(loop)
    commands.estop_now(loop.state, loop.ctx, bus)
    assert loop.state.hold_deadline_s is None and loop.state.source is None
    with pytest.raises(MotionRefused, match="e-stop"):
        heartbeat(loop)


def test_the_speed_is_capped_at_the_jog_limit() -> None:
    limit = SETTINGS.jog.max_velocity_m_s
    loop, _, _ = held((10.0 * limit, 10.0 * limit, 0.0))
    velocity = loop.state.hold_velocity_m_s
    assert np.linalg.norm(velocity) == pytest.approx(limit)


@pytest.mark.parametrize("asked", [1e200, 1e10, 10.0])
def test_an_absurd_speed_is_capped_at_the_jog_speed_in_its_direction(asked: float) -> None:
    loop, _, _ = held()
    used = held_jog.hold_jog(loop.state, loop.ctx, np.array([asked, 0.0, 0.0]), loop._now())
    cap = loop.ctx.jog_limits.velocity
    assert used["velocity_m_s"] == pytest.approx([cap, 0.0, 0.0])  # not a stop, not a sprint

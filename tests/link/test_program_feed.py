"""A running program steered at the robot node (app/robot/node.py ``steer``), its commands
signed and delivered as a link delivers them: pause stands along the checked path, feed
override slows it, single step and M0 stop exactly, and the node's snapshot carries the
state (paused, feed override, line, time left) to the station. The loop runs on a fake bus
on simulated time (app/control/sim_time.py)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from app.config import load_settings
from app.control.controller import Controller
from app.control.errors import MotionRefused
from app.control.sim_time import SteppedClock
from app.link.codec import plain
from app.programs.check import plan_limits
from app.programs.modal import interpret
from app.programs.planner import plan_program
from app.programs.tokens import tokenize
from app.robot.node import RobotNode
from app.runs.source import TrajectorySource
from app.runs.trajectories import plan_sinusoid
from tests.link.test_node import answer, take
from tests.support.fake_bus import FakeBus

SETTINGS = load_settings()
# from where the robot rests: 10 mm along x at 12 mm/s (line 2), an M0 (line 3), back in
# two moves (lines 4 and 5)
PROGRAM = "G21 G91 F720\nG1 X10\nM0\nG1 X-5\nG1 X-5\nM2"


@pytest.fixture
def rig() -> Iterator[tuple[RobotNode, SteppedClock]]:
    clock = SteppedClock(SETTINGS.loop.rate_hz)
    controller = Controller(SETTINGS, FakeBus(), "fake", clock=clock.now, tick_clock=clock)  # type: ignore[arg-type]
    node = RobotNode(SETTINGS, controller, station_timeout_s=None)
    node.start()
    take(node, "a")
    yield node, clock
    node.stop()


def _start_program(node: RobotNode, **play) -> np.ndarray:
    """The program planned from where the robot rests, sent as the station sends it; its
    sampled points [m] (n, 3)."""
    answer(node, "torque", {"enabled": True})
    start = node.controller.snapshot().start_m
    segments = interpret(tokenize(PROGRAM), start, (0.0, 0.0, 0.0)).segments
    source = TrajectorySource(plan_sinusoid(plan_program(segments, plan_limits(SETTINGS)), start))
    path = source.sampled(node.controller.period_s)
    args = {
        "source_id": "prog-1",
        "path": plain(path),
        "expected_start_m": start.tolist(),
        "tolerance_m": 0.002,
        "model_version": 0,
        "play": play,
    }
    assert answer(node, "run_path", args) == "test"
    return np.asarray(path.points_m)


def _steer(node: RobotNode, action: str, **values) -> dict:
    return answer(node, "steer", {"source_id": "prog-1", "action": action, **values})


def test_pause_stands_on_the_path_and_resume_goes_on(rig) -> None:
    node, clock = rig
    points = _start_program(node)
    clock.advance(0.3)
    moving = node.controller.snapshot()
    assert moving.source_feed.rate == 1.0 and moving.source_line == 2
    assert _steer(node, "pause")["paused"] == "pausing"
    clock.advance(1.0)  # far more than it takes to stand (at most 0.5 s)
    snap = node.controller.snapshot()
    assert snap.source_feed.paused == "paused" and snap.source_feed.rate == 0.0
    assert snap.source_line == 2 and snap.mode == "test"  # still the run, on its line
    # the goal on the sampled path: the distance to its nearest sample segment is 0
    a, b = points[:-1], points[1:]
    u = np.clip(
        ((snap.goal_m - a) * (b - a)).sum(1) / np.maximum(((b - a) ** 2).sum(1), 1e-300), 0, 1
    )
    assert np.linalg.norm(a + u[:, None] * (b - a) - snap.goal_m, axis=1).min() < 1e-9
    clock.advance(0.5)
    np.testing.assert_array_equal(node.controller.snapshot().goal_m, snap.goal_m)  # it stands
    assert snap.source_t_s == node.controller.snapshot().source_t_s
    _steer(node, "resume")
    clock.advance(0.2)
    assert node.controller.snapshot().source_t_s > snap.source_t_s


def test_a_feed_override_slows_the_path_and_time_left_grows(rig) -> None:
    node, clock = rig
    _start_program(node, override=0.5)  # as the page starts it: at 50 %
    clock.advance(0.5)
    snap = node.controller.snapshot()
    assert snap.source_feed.override == 0.5 and snap.source_feed.rate == 0.5
    # half as far along the path as the loop's time: at 50 % after a ramp from 100 %
    slew_s = 0.5 / min(2.0, 0.5 / 0.1)  # the ramp from 1.0 to 0.5 [s] (peak speed 0.1 m/s)
    assert snap.source_t_s <= 0.5 * 0.5 + 0.5 * slew_s + 0.02
    left = snap.source_feed.time_left_s
    state = _steer(node, "feed", override=1.0)
    assert state["override"] == 1.0 and state["time_left_s"] == pytest.approx(left / 2, rel=0.01)


def test_m0_stops_the_program_and_a_step_stops_at_the_lines_end(rig) -> None:
    node, clock = rig
    _start_program(node)
    clock.advance(2.0)  # line 2 lasts about 1 s: the M0 on line 3 stops it
    snap = node.controller.snapshot()
    assert snap.source_feed.paused == "M0 at line 3: press Resume" and snap.source_line == 3
    assert snap.source_feed.stop_line == 3 and snap.mode == "test"
    stood = snap.source_t_s
    clock.advance(1.0)
    assert node.controller.snapshot().source_t_s == stood
    _steer(node, "step")  # line 4 to its end, then stand there
    clock.advance(3.0)
    snap = node.controller.snapshot()
    assert snap.source_feed.paused == "single step: stopped at the end of line 4"
    assert snap.mode == "test" and snap.source_line == 4


@pytest.mark.parametrize(
    ("args", "error", "words"),
    [
        ({"action": "feed", "override": 1.5}, ValueError, "override: 150 % is outside 10 to 100 %"),
        ({"action": "feed", "override": "fast"}, ValueError, "override: expected a number"),
        ({"action": "faster"}, ValueError, "action: expected pause, resume"),
        ({"action": "pause", "source_id": "other"}, MotionRefused, "no longer playing"),
    ],
)
def test_a_bad_steer_is_refused_naming_it_and_nothing_changes(rig, args, error, words) -> None:
    node, clock = rig
    _start_program(node)
    clock.advance(0.1)
    with pytest.raises(error, match=words):
        answer(node, "steer", {"source_id": "prog-1", **args})
    clock.advance(0.1)
    assert node.controller.snapshot().source_feed.rate == 1.0
    assert node.controller.snapshot().source_feed.paused is None


def test_only_the_links_holder_steers(rig) -> None:
    from app.link.protocol import LinkRefused

    node, clock = rig
    _start_program(node)
    with pytest.raises(LinkRefused):
        answer(node, "steer", {"source_id": "prog-1", "action": "pause"}, station="b")
    clock.advance(0.1)
    assert node.controller.snapshot().source_feed.paused is None

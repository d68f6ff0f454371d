"""A robot node's commands (app/robot/node.py), called as a link delivers them: each op's
arguments are checked again at the node, a refusal names the argument, and nothing but an
e-stop is taken from a station that does not hold the link. The loop runs on a fake bus
on simulated time (app/control/sim_time.py): each command's tick is run for it."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from app.config import load_settings
from app.control.controller import Controller
from app.control.errors import GoalRejected, MotionRefused
from app.control.sim_time import SteppedClock
from app.link.protocol import LinkRefused, error_of, exception_of
from app.robot.node import RobotNode
from tests.support.fake_bus import HOME_M, FakeBus

SETTINGS = load_settings()


@pytest.fixture
def node() -> Iterator[RobotNode]:
    clock = SteppedClock(SETTINGS.loop.rate_hz)
    bus = FakeBus()
    controller = Controller(SETTINGS, bus, "fake", clock=clock.now, tick_clock=clock)  # type: ignore[arg-type]
    node = RobotNode(SETTINGS, controller, station_timeout_s=None)
    node.start()
    node.call("a", "link", {}).result(timeout=5)
    yield node
    node.stop()


def answer(node: RobotNode, op: str, args: dict | None = None, station: str = "a"):
    """The op's answer, or its refusal as it would cross the link and be raised again."""
    future = node.call(station, op, args)
    error = future.exception(timeout=5)
    if error is not None:
        raise exception_of(error_of(error))
    return future.result()[0]


def test_nothing_but_an_e_stop_from_a_station_without_the_link(node: RobotNode) -> None:
    for op in ("torque", "goal", "jog", "reset", "set_gains", "run_path", "hold", "pose"):
        with pytest.raises(LinkRefused, match="does not hold the robot's link") as refused:
            answer(node, op, {}, station="b")
        assert refused.value.holder == "a"
    answer(node, "estop", {}, station="b")
    assert node.controller.snapshot().estopped


@pytest.mark.parametrize(
    ("op", "args", "words"),
    [
        ("goal", {"point_m": [0.0, 0.0]}, "point_m: expected 3 finite numbers"),
        ("goal", {"point_m": [0.0, 0.0, float("nan")]}, "point_m: expected 3 finite"),
        ("goal", {"point_m": "here"}, "point_m: expected 3"),
        ("jog", {"delta_m": [0, 0, 0.001], "speed_m_s": "fast"}, "speed_m_s: expected a finite"),
        ("torque", {"enabled": "yes"}, "enabled: expected true or false"),
        ("set_gains", {"gains": {"1": {"p": 800, "q": 1}}}, "gains: "),
        ("set_gains", {"gains": [1, 2]}, "gains: expected an object"),
        ("run_path", {"source_id": "x", "path": {}}, "SampledPath.period_s: missing"),
        ("use_model", {"robot": {"kind": "hexapod"}}, "robot.kind: expected one of"),
        ("hold", {"source": "moon", "source_id": "h"}, "source: expected one of"),
        ("pose", {"pose": {"body": "cat"}}, "body: 'cat' is not one of"),
        ("no_such_op", {}, "op: no command 'no_such_op'"),
    ],
)
def test_a_bad_argument_is_refused_naming_it_and_nothing_moves(node, op, args, words) -> None:
    answer(node, "torque", {"enabled": True})
    before = node.controller.snapshot()
    with pytest.raises((ValueError, GoalRejected)) as refused:
        answer(node, op, args)
    assert words in str(refused.value)
    after = node.controller.snapshot()
    assert after.mode == before.mode == "idle"
    np.testing.assert_allclose(after.point_commanded_m, before.point_commanded_m, atol=1e-12)


def test_a_goal_checked_against_another_model_is_refused(node: RobotNode) -> None:
    answer(node, "torque", {"enabled": True})
    with pytest.raises(MotionRefused, match="the robot model changed since this was checked"):
        answer(node, "goal", {"point_m": HOME_M.tolist(), "model_version": 7})
    answer(node, "goal", {"point_m": (HOME_M + [0.01, 0, 0]).tolist(), "model_version": 0})
    assert node.controller.snapshot().mode == "jog"


def test_a_lost_station_stops_a_jog_and_the_node_holds(node: RobotNode) -> None:
    """The node's side of a lost link (tests/link/test_processes.py has the processes)."""
    clock = [0.0]
    node.holder._clock = lambda: clock[0]  # the holder's clock, moved by the test
    node.holder.timeout_s = 0.06
    answer(node, "link", {})
    answer(node, "torque", {"enabled": True})
    answer(node, "move", {"point_m": (HOME_M + [0.05, 0, 0]).tolist(), "duration_s": 2.0})
    assert node.controller.snapshot().mode == "move"
    node.controller.submit(lambda: None).result(timeout=5)  # a tick: a's heartbeat is fresh
    assert node.controller.snapshot().mode == "move"
    clock[0] += 0.07  # no heartbeat for 70 ms
    node.controller.submit(lambda: None).result(timeout=5)  # the tick that sees it lost
    node.controller.submit(lambda: None).result(timeout=5)  # the stop it queued
    snap = node.controller.snapshot()
    assert snap.mode == "idle" and "station's link was lost" in snap.notice
    assert node.holder.view().losses == 1 and not snap.estopped
    with pytest.raises(LinkRefused):  # a's authority went with its heartbeat ...
        node.holder.require("a")
    answer(node, "link", {})  # ... until it takes the link again


def test_a_goal_the_gate_refuses_moves_nothing_at_the_node(node: RobotNode) -> None:
    """The node checks a goal again, whatever its station checked: refused, the loop's
    command and mode do not change (a refusal after the jog was queued would move it)."""
    answer(node, "torque", {"enabled": True})
    before = node.controller.snapshot()
    with pytest.raises(GoalRejected, match="outside the workspace"):
        answer(node, "goal", {"point_m": [1.0, 0.0, -0.24]})
    for _ in range(3):  # ticks after the refusal: nothing was queued
        node.controller.submit(lambda: None).result(timeout=5)
    after = node.controller.snapshot()
    assert after.mode == "idle" and np.allclose(after.goal_m, before.goal_m, equal_nan=True)
    np.testing.assert_allclose(after.point_commanded_m, before.point_commanded_m, atol=1e-12)

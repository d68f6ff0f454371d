"""A robot node's commands (app/robot/node.py), called as a link delivers them: each op's
arguments are checked again at the node, a refusal names the argument, and nothing but an
e-stop is taken from a station that does not hold the link. The loop runs on a fake bus
on simulated time (app/control/sim_time.py): each command's tick is run for it."""

from __future__ import annotations

import dataclasses
import itertools
import json
from collections.abc import Iterator

import numpy as np
import pytest

from app.config import load_settings
from app.control.controller import Controller
from app.control.errors import GoalRejected, MotionRefused
from app.control.sim_time import SteppedClock
from app.link.protocol import LinkRefused, error_of, exception_of, sign
from app.robot.node import RobotNode
from tests.support.fake_bus import HOME_M, FakeBus

SETTINGS = load_settings()


KEYS: dict[str, bytes] = {}
SEQ = itertools.count(1)


@pytest.fixture
def node() -> Iterator[RobotNode]:
    clock = SteppedClock(SETTINGS.loop.rate_hz)
    bus = FakeBus()
    controller = Controller(SETTINGS, bus, "fake", clock=clock.now, tick_clock=clock)  # type: ignore[arg-type]
    node = RobotNode(SETTINGS, controller, station_timeout_s=None)
    node.start()
    take(node, "a")
    yield node
    node.stop()


def take(node: RobotNode, station: str) -> None:
    """``station`` takes the link; its key signs its commands from now on."""
    result, _ = node.call(station, "link", {}).result(timeout=5)
    KEYS[station] = bytes.fromhex(result["key"])


def answer(node: RobotNode, op: str, args: dict | None = None, station: str = "a"):
    """The op's answer, or its refusal as it would cross the link and be raised again;
    signed with ``station``'s key (none: a station that never took the link)."""
    body = json.dumps(args or {}).encode()
    seq = next(SEQ)
    mac = sign(KEYS.get(station, b"none"), station, op, seq, body)
    future = node.call(station, op, json.loads(body), auth=(seq, mac, body))
    error = future.exception(timeout=5)
    if error is not None:
        raise exception_of(error_of(error))
    return future.result()[0]


def test_nothing_but_an_e_stop_from_a_station_without_the_link(node: RobotNode) -> None:
    for op in ("torque", "goal", "jog", "reset", "set_gains", "run_path", "hold", "pose", "tap"):
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
    take(node, "a")
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
        answer(node, "torque", {"enabled": True})
    take(node, "a")  # ... until it takes the link again
    answer(node, "torque", {"enabled": True})


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


def _run_args(node: RobotNode, change=None, **extra) -> dict:
    """A planned sinusoid from where the robot rests, as the station sends it."""
    from app.link.codec import plain
    from app.runs.source import TrajectorySource
    from app.runs.trajectories import SinusoidParams, plan_sinusoid

    start = node.controller.snapshot().start_m
    params = SinusoidParams(amplitude_m=(0.01, 0.01, 0.0), offset_m=tuple(start), duration_s=0.5)
    source = TrajectorySource(plan_sinusoid(params, start), lead_s=0.01)
    path = source.sampled(node.controller.period_s)
    if change is not None:
        path = change(path)
    args = {
        "source_id": "run-1",
        "path": plain(path),
        "expected_start_m": start.tolist(),
        "tolerance_m": 0.002,
        "model_version": 0,
    }
    return {**args, **extra}


@pytest.mark.parametrize(
    ("change", "extra", "words"),
    [
        (None, {"tolerance_m": None}, "tolerance_m: expected a finite number"),
        (None, {"tolerance_m": 0.5}, "tolerance_m: a run starts within 10 mm"),
        (
            lambda p: dataclasses.replace(p, points_m=p.points_m + [0.05, 0, 0]),
            {},
            "path.points_m: the first sample is not the run's start point",
        ),
        (
            lambda p: dataclasses.replace(
                p,
                commanded_m=p.commanded_m
                + np.where(np.arange(len(p.points_m))[:, None] == 40, [0.1, 0, 0], 0),
            ),
            {},
            "path.commanded_m: sample 40 is 100.0 mm from the goal",
        ),
        (
            lambda p: dataclasses.replace(
                p,
                points_m=np.where(
                    np.arange(len(p.points_m))[:, None] == 60, [0.0, 0.0, -0.9], p.points_m
                ),
                commanded_m=None,
            ),
            {},
            "outside the workspace",
        ),
    ],
)
def test_a_run_is_checked_again_at_the_node_before_it_moves(node, change, extra, words) -> None:
    answer(node, "torque", {"enabled": True})
    with pytest.raises((ValueError, GoalRejected), match=words):
        answer(node, "run_path", _run_args(node, change, **extra))
    assert node.controller.snapshot().mode == "idle"


def test_a_run_the_node_finds_sound_is_played(node: RobotNode) -> None:
    answer(node, "torque", {"enabled": True})
    assert answer(node, "run_path", _run_args(node)) == "test"
    assert node.controller.snapshot().source_id == "run-1"

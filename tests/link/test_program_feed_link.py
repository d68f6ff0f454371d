"""A program paused, slowed and resumed over the real link: a robot node (`deltadash robot` on
the twin) in a process of its own, a station in this test's process (a RobotClient over
Zenoh) that sends the program's samples and steers them, and a passive listener on the
node's state key that reads what the robot does. Waits are conditions with deadlines."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.programs.check import plan_limits
from app.programs.modal import interpret
from app.programs.planner import plan_program
from app.programs.tokens import tokenize
from app.runs.source import TrajectorySource
from app.runs.trajectories import plan_sinusoid
from tests.link.test_processes import _ready
from tests.support.robot_node import robot_node, station, watch
from tests.support.server import wait_for

pytestmark = pytest.mark.slow  # real processes, the twin in real time
# relative moves from where the arm holds: 20 mm along x at 4 mm/s (line 2, 5 s), back
PROGRAM = "G21 G91 F240\nG1 X20\nG1 X-20\nM2"


def test_a_program_paused_over_the_link_stands_on_its_path_and_goes_on(tmp_path: Path) -> None:
    with (
        robot_node(tmp_path) as node,
        watch(node.endpoint) as seen,
        station(node.endpoint) as client,
    ):
        _ready(client)
        start = client.snapshot().start_m
        segments = interpret(tokenize(PROGRAM), start, (0.0, 0.0, 0.0)).segments
        path = plan_program(segments, plan_limits(client.settings))
        source = TrajectorySource(plan_sinusoid(path, start))
        source.start_play["override"] = 0.5  # as the page's slider would start it
        client.run_source(source, start, 0.002).result(timeout=10)
        wait_for(
            lambda: seen.latest.source_line == 2 and seen.latest.source_feed is not None,
            "line 2 under way",
            seen=lambda: seen.latest.source_feed,
        )
        assert seen.latest.source_feed.override == 0.5
        state = client.steer_source(source, "pause").result(timeout=10)
        assert state["paused"] in ("pausing", "paused")
        wait_for(
            lambda: seen.latest.source_feed.paused == "paused",
            "the program standing",
            seen=lambda: seen.latest.source_feed,
        )
        # the station's copy of the source follows the node's snapshots
        wait_for(
            lambda: source.feed_state is not None and source.feed_state.paused == "paused",
            "the station's copy paused",
            seen=lambda: source.feed_state,
        )
        assert source.program_line == 2
        goal = seen.latest.goal_m.copy()
        count = len(seen.seen)
        wait_for(lambda: len(seen.seen) > count + 50, "50 more states")
        stood = [s.goal_m for s in seen.since(seen.seen[count][0])]
        assert all(np.array_equal(g, goal) for g in stood)
        # on line 2's straight path: y and z as at the start, x between start and end
        assert goal[1] == pytest.approx(start[1], abs=1e-9)
        assert goal[2] == pytest.approx(start[2], abs=1e-9)
        assert start[0] < goal[0] < start[0] + 0.02
        with pytest.raises(ValueError, match="override: 150 %"):
            client.steer_source(source, "feed", override=1.5).result(timeout=10)
        client.steer_source(source, "feed", override=1.0).result(timeout=10)
        client.steer_source(source, "resume").result(timeout=10)
        wait_for(lambda: seen.latest.mode != "test", "the program's end", timeout_s=120)
        assert seen.latest.finished_source_id == source.source_id

"""The link between a station and a robot node, as two real processes over loopback.

A robot node (`deltadash robot` on the twin) in a process of its own; the station either
in this test's process (a RobotClient over Zenoh) or `deltadash serve --robot` in
another. What the robot does is read by a third, passive Zenoh session on the node's
state key (tests/support/robot_node.py ``watch``), so a station that was killed or
stopped cannot colour what the test sees. Waits are conditions with deadlines.
"""

from __future__ import annotations

import json
import os
import signal
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.control.errors import GoalRejected
from app.link.protocol import LinkRefused, RobotOffline
from tests.support.robot_node import node_env, robot_node, station, watch
from tests.support.server import serve, wait_for

pytestmark = pytest.mark.slow  # real processes: a node, a station, the twin in real time
START_M = [0.0, 0.0, -0.24]


def _at_rest(client) -> bool:
    """Torque on once the arm that fell at power-up rests inside its limits."""
    try:
        client.set_torque(True).result(timeout=10)
    except Exception:
        return False
    return client.snapshot().torque


def _ready(client) -> None:
    wait_for(lambda: _at_rest(client), "torque on at rest", seen=lambda: client.snapshot().mode)
    client.move(point=START_M).result(timeout=10)
    wait_for(
        lambda: (
            np.linalg.norm(client.snapshot().point_measured_m - START_M) < 2e-3
            and client.snapshot().mode != "move"
        ),
        "the arm at the start point",
        seen=lambda: client.snapshot().point_measured_m,
    )


def test_a_station_commands_the_node_and_a_refused_goal_moves_nothing(tmp_path: Path) -> None:
    with robot_node(tmp_path) as node, watch(node.endpoint) as seen, station(node.endpoint) as a:
        assert a.backend == "sim" and a.servo_ids == (1, 2, 3)
        _ready(a)
        goal = [0.03, 0.0, -0.24]
        a.set_goal(goal).result(timeout=10)
        wait_for(
            lambda: (
                seen.latest is not None
                and np.allclose(seen.latest.goal_m, goal, atol=1e-9)
                and np.allclose(seen.latest.point_commanded_m, goal, atol=1e-6)
            ),
            "the node at the goal, as its own state says",
        )
        held = seen.latest.point_commanded_m.copy()
        # refused at the station (its mirror of the node's gate) with the API's words
        with pytest.raises(GoalRejected, match="outside the workspace; nearest reachable point"):
            a.set_goal([1.0, 0.0, -0.24])
        # and refused by the node itself, whatever a station sends
        refused = a.request("goal", {"point_m": [1.0, 0.0, -0.24]})  # unchecked at the station
        with pytest.raises(GoalRejected, match="outside the workspace"):
            refused.result(timeout=10)
        after = time.monotonic()
        wait_for(lambda: len(seen.since(after)) > 60, "the states after the refusals")
        tail = [s.point_commanded_m for s in seen.since(after)]
        assert tail and all(np.allclose(p, held, atol=1e-6) for p in tail)


def test_a_second_station_needs_an_explicit_take_over(tmp_path: Path) -> None:
    with robot_node(tmp_path) as node, station(node.endpoint) as a:
        with (
            pytest.raises(LinkRefused, match=f"station {a.station_id} holds") as refused,
            station(node.endpoint),
        ):
            pass
        assert refused.value.holder == a.station_id
        with station(node.endpoint, take_over=True) as b:
            assert b.took_over_from == a.station_id
            with pytest.raises(LinkRefused) as lost:  # a's commands are refused now
                a.set_torque(True).result(timeout=10)
            assert lost.value.holder == b.station_id
        assert "took the robot's link over" in node.text()


def _station_api(server, method: str, path: str, body: dict | None, lease: str) -> Any:
    request = urllib.request.Request(
        server.url + path,
        data=None if body is None else json.dumps(body).encode(),
        method=method,
        headers={"Content-Type": "application/json", "X-Lease": lease},
    )
    with urllib.request.urlopen(request, timeout=15) as response:
        return json.load(response)


def _lease(server) -> str:
    return server.post("/api/lease", {"client": "link test", "take_over": True})["lease_id"]


def _rest_and_move(server, lease: str) -> None:
    def torque() -> bool:
        try:
            _station_api(server, "POST", "/api/torque", {"enabled": True}, lease)
            return True
        except urllib.error.HTTPError:
            return False

    wait_for(torque, "torque on at rest")
    _station_api(server, "POST", "/api/move", {"position_m": START_M}, lease)
    wait_for(
        lambda: server.get("/api/status")["mode"] == "idle",
        "the move to the start point done",
        seen=server.brief,
    )


@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGSTOP])
def test_a_lost_station_stops_the_move_it_commanded(tmp_path: Path, signum: int) -> None:
    # short enough to stop the motion early, long enough that a busy 2-core machine's
    # heartbeat gaps do not lose the link while the test sets up
    env = node_env(station_timeout_s=0.5)
    with (
        robot_node(tmp_path, **env) as node,
        watch(node.endpoint) as seen,
        serve(tmp_path, DELTADASH_LINK__ROBOT=node.endpoint) as server,
    ):
        lease = _lease(server)
        _rest_and_move(server, lease)
        far = [0.06, 0.0, -0.24]
        _station_api(server, "POST", "/api/move", {"position_m": far, "duration_s": 6.0}, lease)
        wait_for(lambda: seen.latest.mode == "move", "the slow move under way")
        server.process.send_signal(signum)
        try:
            lost = time.monotonic()
            wait_for(
                lambda: seen.latest.mode != "move",
                "the node to stop the lost station's move",
                seen=lambda: (seen.latest.mode, seen.latest.notice),
            )
            stopped = seen.latest
            assert "station's link was lost" in (stopped.notice or "")
            assert np.linalg.norm(stopped.point_commanded_m - far) > 0.01  # stopped short
            # and it stays where it stopped: nothing moves until a station acts
            wait_for(lambda: len(seen.since(lost + 1.0)) > 50, "a second of states after")
            held = [s.point_commanded_m for s in seen.since(lost + 1.0)]
            assert all(np.allclose(p, held[0], atol=1e-6) for p in held)
            assert "lost the robot's link" in node.text()
        finally:
            if signum == signal.SIGSTOP:
                server.process.send_signal(signal.SIGCONT)
        if signum == signal.SIGSTOP:  # back: its next command takes the link again
            _station_api(server, "POST", "/api/goal", {"position_m": START_M}, lease)
            wait_for(lambda: seen.latest.mode == "jog", "the station's goal, after it came back")


def test_a_killed_node_is_offline_at_the_station_and_linked_again_once_back(
    tmp_path: Path,
) -> None:
    endpoint_node = robot_node(tmp_path)
    with endpoint_node as node, serve(tmp_path, DELTADASH_LINK__ROBOT=node.endpoint) as server:
        lease = _lease(server)
        _rest_and_move(server, lease)
        node.kill()
        node.process.wait()

        def offline() -> str | None:
            try:
                server.get("/api/status")
                return None
            except urllib.error.HTTPError as exc:
                return exc.read().decode() if exc.code == 503 else None

        said = wait_for(offline, "the station to say the robot is offline", seen=server.brief)
        assert "robot offline" in said
        with pytest.raises(urllib.error.HTTPError) as refused:
            _station_api(server, "POST", "/api/torque", {"enabled": True}, lease)
        assert refused.value.code == 503
        with robot_node(tmp_path, endpoint=node.endpoint):  # the same endpoint, a new node
            wait_for(lambda: offline() is None, "the station online again", seen=server.brief)
            _rest_and_move(server, lease)  # its commands take the new node's link


def test_a_station_without_the_links_password_is_refused(tmp_path: Path) -> None:
    login = {"user": "lab", "password": "correct horse"}
    with robot_node(tmp_path, **node_env(**login)) as node:
        with (
            pytest.raises(RobotOffline),
            station(node.endpoint, user="lab", password="wrong password"),
        ):
            pass
        with pytest.raises(RobotOffline), station(node.endpoint):  # no login at all
            pass
        with station(node.endpoint, **login) as a:
            assert a.backend == "sim"


@pytest.mark.parametrize("signum", [signal.SIGSTOP, signal.SIGKILL])
def test_the_pages_e_stop_reaches_the_node_with_the_station_hung_or_killed(
    tmp_path: Path, signum: int
) -> None:
    with (
        robot_node(tmp_path) as node,
        watch(node.endpoint) as seen,
        serve(tmp_path, DELTADASH_LINK__ROBOT=node.endpoint) as server,
    ):
        info = server.get("/api/info")  # what the page reads at load: the node's listener
        assert info["estop_port"] and info["estop_host"] is None  # a node on this machine
        lease = _lease(server)
        _rest_and_move(server, lease)
        far = [0.06, 0.0, -0.24]
        _station_api(server, "POST", "/api/move", {"position_m": far, "duration_s": 6.0}, lease)
        wait_for(lambda: seen.latest.mode == "move", "the slow move under way")
        server.process.send_signal(signum)
        try:
            request = urllib.request.Request(
                f"http://127.0.0.1:{info['estop_port']}/estop?press=hung-station",
                method="POST",
                headers={"Origin": server.url},
            )
            with urllib.request.urlopen(request, timeout=15) as answer:
                assert answer.status == 200
                assert answer.headers["Access-Control-Allow-Origin"] == server.url
            wait_for(
                lambda: seen.latest.estopped, "the node e-stopped", seen=lambda: seen.latest.mode
            )
            assert seen.latest.mode == "estop"
        finally:
            if signum == signal.SIGSTOP:
                server.process.send_signal(signal.SIGCONT)
        if signum == signal.SIGSTOP:  # back, the station's status shows the node's receipt
            status = wait_for(
                lambda: (got := server.get("/api/status"))["estop_arrivals_unix_s"] and got,
                "the node's receipt of the press in the station's status",
            )
            assert status["estopped"] and "listener" in status["estop_arrivals_unix_s"]


def test_a_station_killed_mid_run_leaves_the_robot_holding_where_the_run_was(
    tmp_path: Path,
) -> None:
    """link.on_station_lost = stop (the default): the node stops the run it was playing
    and holds; the station's next start finds the run interrupted."""
    # short enough to stop the motion early, long enough that a busy 2-core machine's
    # heartbeat gaps do not lose the link while the test sets up
    env = node_env(station_timeout_s=0.5)
    with (
        robot_node(tmp_path, **env) as node,
        watch(node.endpoint) as seen,
        serve(tmp_path, DELTADASH_LINK__ROBOT=node.endpoint) as server,
    ):
        lease = _lease(server)
        _rest_and_move(server, lease)
        body = {"duration_s": 20.0, "amplitude_m": [0.02, 0.02, 0.0]}
        _station_api(server, "POST", "/api/tests/sinusoid", body, lease)
        wait_for(
            lambda: seen.latest.mode == "test" and seen.latest.phase == "timed",
            "the run's timed part under way",
            seen=lambda: (seen.latest.mode, seen.latest.phase),
        )
        server.process.kill()
        lost = time.monotonic()
        wait_for(lambda: seen.latest.mode != "test", "the node to stop the run")
        assert "station's link was lost" in (seen.latest.notice or "")
        wait_for(lambda: len(seen.since(lost + 1.0)) > 50, "a second of states after")
        held = [s.point_commanded_m for s in seen.since(lost + 1.0)]
        assert all(np.allclose(p, held[0], atol=1e-6) for p in held)


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            found.append(int(entry.name))
    return found


def test_the_embedded_node_is_started_again_when_it_dies(tmp_path: Path) -> None:
    """`deltadash serve` with no robot named runs the loop in a child robot node and
    supervises it: killed, it is started again and the station takes its link again."""
    with serve(tmp_path) as server:
        lease = _lease(server)
        _rest_and_move(server, lease)
        nodes = [
            pid
            for pid in _children(server.process.pid)
            if b"robot" in Path(f"/proc/{pid}/cmdline").read_bytes()
        ]
        assert len(nodes) == 1, nodes
        os.kill(nodes[0], signal.SIGKILL)

        def linked_again() -> bool:
            try:
                return server.get("/api/status")["mode"] in ("idle", "jog")
            except urllib.error.HTTPError:
                return False

        wait_for(lambda: not linked_again(), "the station to see its node gone", seen=server.brief)
        wait_for(linked_again, "the node started again and linked", seen=server.brief)
        assert "the robot node exited" in server.log.read_text()
        _rest_and_move(server, lease)  # and it moves the robot again

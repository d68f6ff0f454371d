"""deltadash in a ROS 2 graph over Zenoh, seen and driven by an independent peer.

Three real processes: a robot node (`deltadash robot` on the twin), an independent ROS 2
peer (zenoh-ros2-sdk, tests/ros2/peer.py) and this test's own station (a RobotClient over
the link) where an operator's authority is needed. The peer computes its type hashes from
its own message definitions, so a topic it receives is one whose key, type and hash a ROS
2 graph would match; raw samples are read here too, their CDR decoded by
mcap-ros2-support and their attachments by the SDK. Waits are conditions with deadlines.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh
from zenoh_ros2_sdk.attachment import Attachment

from app.config import LinkSettings, Settings
from app.link.zenoh_session import zenoh_config
from app.ros2 import graph
from app.ros2.messages import JOINT_STATE, POSE, typestore
from kinematics import THESIS_DELTA
from kinematics.tool import Tool
from tests.ros2.definitions import decoder
from tests.support.robot_node import robot_node, station
from tests.support.server import free_port, serve, wait_for

pytestmark = pytest.mark.slow  # real processes: a node on the twin in real time, a peer
PEER = Path(__file__).resolve().parent / "peer.py"
START_M = [0.0, 0.0, -0.24]


class Peer:
    """The independent peer's process: commands in, JSON lines out."""

    def __init__(self, endpoint: str, domain: int, **env: str) -> None:
        host, port = endpoint.removeprefix("tcp/").rsplit(":", 1)
        self.process = subprocess.Popen(
            [sys.executable, str(PEER), host, port, str(domain)],
            env={**os.environ, **env},
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: list[dict[str, Any]] = []
        self.text: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()
        wait_for(lambda: self.find(ready=True), "the peer ready", seen=lambda: self.text[-5:])

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.text.append(line)
            with suppress(ValueError):
                self.lines.append(json.loads(line))

    def find(self, **match: Any) -> list[dict[str, Any]]:
        return [x for x in list(self.lines) if all(x.get(k) == v for k, v in match.items())]

    def ask(self, **command: Any) -> dict[str, Any]:
        before = len(self.lines)
        assert self.process.stdin is not None
        self.process.stdin.write(json.dumps(command) + "\n")
        self.process.stdin.flush()

        def answer() -> dict[str, Any] | None:
            for line in self.lines[before:]:
                if line.get("op") == command["op"] or "error" in line:
                    return line
            return None

        found = wait_for(
            answer, f"the peer's answer to {command['op']}", seen=lambda: self.text[-5:]
        )
        assert "error" not in found, found
        return found

    def messages(self, topic: str) -> list[dict[str, Any]]:
        return [x["message"] for x in self.find(topic=topic) if "message" in x]

    def close(self) -> None:
        self.process.kill()
        self.process.wait()


@contextmanager
def ros_robot(folder: Path, **env: str) -> Iterator[tuple[Any, Peer, int]]:
    """A robot node with its ROS side on a domain of its own, and the peer."""
    domain = random.randint(1, 200)
    # a peer's message stamped "now" can arrive over 0.5 s late on a loaded 2-core machine
    # and be refused as old before the check a test looks at (tests/ros2/test_inputs.py
    # tests the stamp's bounds on simulated time)
    env = {"DELTADASH_ROS2__STAMP_AGE_S": "30", **env}
    with robot_node(folder, DELTADASH_ROS2__DOMAIN_ID=str(domain), **env) as node:
        peer = Peer(node.endpoint, domain)
        try:
            yield node, peer, domain
        finally:
            peer.close()


def _ready(client) -> None:
    def at_rest() -> bool:
        try:
            client.set_torque(True).result(timeout=10)
        except Exception:
            return False
        return client.snapshot().torque

    wait_for(at_rest, "torque on at rest", seen=lambda: client.snapshot().mode)
    client.move(point=START_M).result(timeout=10)
    wait_for(
        lambda: (
            np.linalg.norm(client.snapshot().point_measured_m - START_M) < 2e-3
            and client.snapshot().mode != "move"
        ),
        "the arm at the start point",
        seen=lambda: client.snapshot().point_measured_m,
    )


def _stamp(message: dict[str, Any]) -> int:
    stamp = message["header"]["stamp"]
    return stamp["sec"] * 10**9 + stamp["nanosec"]


def test_an_independent_peer_sees_the_robots_topics(tmp_path: Path) -> None:
    with ros_robot(tmp_path) as (node, peer, domain):

        def listed() -> dict[str, list[str]] | None:
            found = dict(peer.ask(op="topics")["topics"])
            return found if len(found) >= 7 else None

        topics = wait_for(listed, "deltadash's topics in the graph")
        assert topics == {
            "/joint_states": ["sensor_msgs/msg/JointState"],
            "/tf": ["tf2_msgs/msg/TFMessage"],
            "/tf_static": ["tf2_msgs/msg/TFMessage"],
            "/delta/tip_pose": ["geometry_msgs/msg/PoseStamped"],
            "/delta/tip_pose_world": ["geometry_msgs/msg/PoseStamped"],
            "/diagnostics": ["diagnostic_msgs/msg/DiagnosticArray"],
            "/delta/tip_wrench": ["geometry_msgs/msg/WrenchStamped"],
        }
        for topic, typename in (
            ("/joint_states", JOINT_STATE),
            ("/tf", "tf2_msgs/msg/TFMessage"),
            ("/delta/tip_pose", POSE),
            ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
            ("/tf_static", "tf2_msgs/msg/TFMessage"),
        ):
            peer.ask(op="subscribe", topic=topic, type=typename)
        wait_for(
            lambda: (
                len(peer.messages("/joint_states")) >= 50
                and peer.messages("/diagnostics")
                and peer.messages("/tf_static")
            ),
            "joint states, diagnostics and /tf_static at the peer",
            seen=lambda: {t: len(peer.messages(t)) for t in ("/joint_states", "/tf_static")},
        )
        # one tick's messages carry its stamp: joints, tf and tip agree through FK
        joints = {_stamp(m): m for m in peer.messages("/joint_states")}
        tfs = {_stamp(m["transforms"][0]): m for m in peer.messages("/tf")}
        tips = {_stamp(m): m for m in peer.messages("/delta/tip_pose")}
        shared = sorted(set(joints) & set(tfs) & set(tips))
        assert len(shared) >= 20
        tool = Tool(offset_m=Settings().tool.offset_m)
        for stamp in shared[-20:]:
            state = joints[stamp]
            assert state["name"] == ["delta_joint_1", "delta_joint_2", "delta_joint_3"]
            platform, tip = tfs[stamp]["transforms"]
            assert (platform["header"]["frame_id"], platform["child_frame_id"]) == (
                "delta_base",
                "delta_platform",
            )
            at = platform["transform"]["translation"]
            centre = np.array([at["x"], at["y"], at["z"]])
            assert centre == pytest.approx(THESIS_DELTA.fk(state["position"]).points, abs=1e-9)
            p = tips[stamp]["pose"]["position"]
            assert [p["x"], p["y"], p["z"]] == pytest.approx(tool.tip(centre, 0.0), abs=1e-9)
        (status,) = peer.messages("/diagnostics")[-1]["status"]
        values = {kv["key"]: kv["value"] for kv in status["values"]}
        assert values["estopped"] == "false" and values["faults"] == "none"
        # OK, or WARN naming why (a loaded machine's loop misses ticks): never ERROR
        assert status["level"] == 0 or (
            status["level"] == 1
            and (int(values["overruns_last_10s"]) > 0 or status["message"] != "idle")
        )
        (mount,) = peer.messages("/tf_static")[0]["transforms"]
        assert (mount["header"]["frame_id"], mount["child_frame_id"]) == ("base_link", "delta_base")

        # raw samples: CDR read by mcap-ros2-support, attachments by the SDK
        raw: list[zenoh.Sample] = []
        config, cleanup = zenoh_config(LinkSettings(), connect=node.endpoint)
        session = zenoh.open(config)
        try:
            key = graph.topic_key("rmw_zenoh", domain, "/joint_states", JOINT_STATE, "*")
            subscriber = session.declare_subscriber(key, raw.append)
            wait_for(lambda: len(raw) >= 10, "raw joint states")
            subscriber.undeclare()
        finally:
            session.close()
            cleanup()
        attachments = [Attachment.from_bytes(s.attachment.to_bytes()) for s in raw[:10]]
        assert [a.sequence_id for a in attachments] == list(
            range(attachments[0].sequence_id, attachments[0].sequence_id + 10)
        )
        assert len({a.gid for a in attachments}) == 1 and len(attachments[0].gid) == 16
        for sample, attachment in zip(raw[:10], attachments, strict=True):
            assert str(sample.encoding) == "application/cdr"
            message = decoder(JOINT_STATE)(sample.payload.to_bytes())
            stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
            assert abs(attachment.timestamp_ns - stamp) < 1000  # the same time, to 1 us


ODOMETRY_AT_REST = {
    "header": {"frame_id": "odom"},
    "child_frame_id": "base_link",
    "pose": {
        "pose": {
            "position": {"x": 0.0, "y": 0.0, "z": 1.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
        "covariance": [0.0] * 36,
    },
    "twist": {
        "twist": {"linear": {"x": 0, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}},
        "covariance": [0.0] * 36,
    },
}


def _goal(frame: str, xyz: list[float]) -> dict[str, Any]:
    now = time.time()
    return {
        "header": {
            "frame_id": frame,
            "stamp": {"sec": int(now), "nanosec": int((now - int(now)) * 1e9)},
        },
        "pose": {
            "position": dict(zip("xyz", xyz, strict=True)),
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
    }


def _ros(client) -> dict[str, Any]:
    return client.request("ros_status", {}).result(timeout=10)


def test_the_peers_odometry_holds_in_the_world_and_its_goals_need_authority(
    tmp_path: Path,
) -> None:
    env = {"DELTADASH_ROS2__POSE_INPUT": "odometry", "DELTADASH_ROS2__GOAL_INPUT": "pose"}
    with ros_robot(tmp_path, **env) as (node, peer, _), station(node.endpoint) as a:
        _ready(a)
        # a goal before the operator arms the input: refused, counted, nothing moves
        peer.ask(
            op="publish",
            topic="/delta/tip_goal",
            type=POSE,
            message=_goal("delta_base", [0.02, 0, -0.24]),
        )
        wait_for(
            lambda: _ros(a)["goal_input"]["refused"].get("unarmed") == 1,
            "the unarmed goal refused",
            seen=lambda: _ros(a)["goal_input"],
        )
        assert np.linalg.norm(a.snapshot().goal_m - START_M) < 1e-9
        armed = a.request("ros_goals", {"enabled": True}).result(timeout=10)
        assert armed["goal_input"]["armed"] is True
        peer.ask(
            op="publish",
            topic="/delta/tip_goal",
            type=POSE,
            message=_goal("delta_base", [0.02, 0, -0.24]),
        )
        wait_for(
            lambda: np.linalg.norm(a.snapshot().point_measured_m - [0.02, 0, -0.24]) < 2e-3,
            "the arm at the peer's goal",
            seen=lambda: (a.snapshot().point_measured_m, _ros(a)["goal_input"]),
        )
        # a goal the gate refuses: counted by its reason, the goal unchanged
        peer.ask(
            op="publish",
            topic="/delta/tip_goal",
            type=POSE,
            message=_goal("delta_base", [0.0, 0, -0.9]),
        )
        wait_for(
            lambda: _ros(a)["goal_input"]["refused"].get("GoalRejected") == 1,
            "the goal outside the workspace refused",
            seen=lambda: _ros(a)["goal_input"],
        )
        assert a.snapshot().goal_m == pytest.approx([0.02, 0, -0.24])

        # the drone's odometry from the peer: a hold in the world follows it
        peer.ask(
            op="stream",
            topic="/odom",
            type="nav_msgs/msg/Odometry",
            message=ODOMETRY_AT_REST,
            rate_hz=50,
        )
        wait_for(
            lambda: _ros(a)["pose_input"]["state"] == "ok",
            "the odometry input ok",
            seen=lambda: _ros(a)["pose_input"],
        )
        a.request("hold", {"source": "external", "source_id": "ros-hold"}).result(timeout=10)
        start = a.snapshot().tick
        wait_for(
            lambda: a.snapshot().mode == "hold-world" and a.snapshot().tick > start + 200,
            "a second of hold-in-world on the peer's odometry",
            seen=lambda: (a.snapshot().mode, a.snapshot().faults),
        )
        world = a.snapshot().extra["goal_world_m"]
        # the drone at 1 m up, level: the tip's world goal is its base point lifted by the
        # mount and the drone
        mount = np.asarray(Settings().world.mount_position_m)
        assert world == pytest.approx(
            np.asarray(a.snapshot().goal_m) + mount + [0, 0, 1.0], abs=2e-3
        )
        # a world-frame goal from the peer moves the hold's goal
        target = [world[0] + 0.01, world[1], world[2]]
        peer.ask(op="publish", topic="/delta/tip_goal", type=POSE, message=_goal("odom", target))
        wait_for(
            lambda: a.snapshot().extra["goal_world_m"] == pytest.approx(target),
            "the hold's world goal moved by the peer",
            seen=lambda: (a.snapshot().extra.get("goal_world_m"), _ros(a)["goal_input"]),
        )
        # a world goal outside the workspace at the drone's pose, and one in a world the
        # drone's pose is not in: refused, counted, the hold's goal unchanged
        peer.ask(
            op="publish", topic="/delta/tip_goal", type=POSE, message=_goal("odom", [0, 0, 5.0])
        )
        peer.ask(op="publish", topic="/delta/tip_goal", type=POSE, message=_goal("map", target))
        wait_for(
            lambda: (
                _ros(a)["goal_input"]["refused"].get("GoalRejected") == 2
                and _ros(a)["goal_input"]["refused"].get("frame") == 1
            ),
            "the far world goal and the one in another world refused",
            seen=lambda: _ros(a)["goal_input"],
        )
        assert a.snapshot().extra["goal_world_m"] == pytest.approx(target)
        # the odometry stops: the hold stops on a lost pose (the input named silent)
        peer.ask(op="stop_streams")
        wait_for(
            lambda: a.snapshot().mode != "hold-world",
            "the hold ended without odometry",
            seen=lambda: a.snapshot().mode,
        )
        assert any("drone pose" in f.reason for f in a.snapshot().faults)
        wait_for(lambda: _ros(a)["pose_input"]["state"] == "silent", "the odometry input silent")
        # disarmed by the operator; armed again, then disarmed by any take of the link,
        # the same station's too (a retake after a loss is not the operator's arming)
        a.request("ros_goals", {"enabled": False}).result(timeout=10)
        assert _ros(a)["goal_input"]["armed"] is False
        a.request("ros_goals", {"enabled": True}).result(timeout=10)
        a.reconnect()
        assert _ros(a)["goal_input"]["armed"] is False


def test_bad_input_on_every_subscribed_topic_is_counted_and_moves_nothing(
    tmp_path: Path,
) -> None:
    env = {"DELTADASH_ROS2__POSE_INPUT": "px4", "DELTADASH_ROS2__GOAL_INPUT": "point"}
    with ros_robot(tmp_path, **env) as (node, peer, domain), station(node.endpoint) as a:
        _ready(a)
        a.request("ros_goals", {"enabled": True}).result(timeout=10)
        config, cleanup = zenoh_config(LinkSettings(), connect=node.endpoint)
        session = zenoh.open(config)
        store = typestore("jazzy")
        types = store.types
        point_type = "geometry_msgs/msg/PointStamped"
        goal_key = graph.topic_key(
            "rmw_zenoh", domain, "/delta/tip_goal", point_type, store.hash_rihs01(point_type)
        )
        elsewhere = graph.topic_key("rmw_zenoh", domain, "/delta/tip_goal", point_type, "RIHS01_0")
        pose_key = graph.topic_key(
            "rmw_zenoh",
            domain,
            "/fmu/out/vehicle_odometry",
            "px4_msgs/msg/VehicleOdometry",
            "RIHS01_0",
        )

        def point(frame: str, xyz: list[float]) -> bytes:
            now = time.time()
            header = types["std_msgs/msg/Header"](
                stamp=types["builtin_interfaces/msg/Time"](
                    sec=int(now), nanosec=int((now - int(now)) * 1e9)
                ),
                frame_id=frame,
            )
            message = types[point_type](
                header=header, point=types["geometry_msgs/msg/Point"](*map(float, xyz))
            )
            return bytes(store.serialize_cdr(message, point_type))

        try:
            good = point("delta_base", [0.0, 0.02, -0.24])
            wait_for(
                lambda: (
                    session.get  # the node's subscriptions are matched
                    and _ros(a)["goal_input"] is not None
                ),
                "the goal input up",
            )
            bad = {
                goal_key: [
                    good[: len(good) // 2],  # truncated
                    b"\x00\x01\x00\x00" + b"\xff" * 8,  # garbage
                    point("delta_base", [float("nan"), 0, -0.24]),  # NaN
                    point("camera", [0.0, 0.0, -0.24]),  # a frame it cannot use
                    b"\x00" * (70 * 1024),  # too big
                ],
                pose_key: [good, b"", point("odom", [0, 0, 1])],  # other types, empty
            }
            for key, payloads in bad.items():
                which = "goal_input" if key == goal_key else "pose_input"
                for payload in payloads:
                    before = _ros(a)[which]["received"]
                    session.put(key, payload)
                    # each counted before the next: apart, not a flood
                    wait_for(lambda w=which, b=before: _ros(a)[w]["received"] > b, "counted")
            # a goal under another type hash is another type to rmw_zenoh: never received
            # (the next one, sent after it on the same session, arrives alone)
            before = _ros(a)["goal_input"]["received"]
            session.put(elsewhere, good)
            session.put(goal_key, point("camera", [0.0, 0.0, -0.24]))
            wait_for(lambda: _ros(a)["goal_input"]["received"] > before, "the next goal")
            assert _ros(a)["goal_input"]["received"] == before + 1
            for _ in range(3000):  # a flood of good goals
                session.put(
                    goal_key,
                    point("delta_base", [0.0, 0.0, -0.24]),
                    congestion_control=zenoh.CongestionControl.BLOCK,
                )
            wait_for(
                lambda: _ros(a)["goal_input"]["received"] >= 3006,
                "every goal counted",
                seen=lambda: _ros(a)["goal_input"],
            )
            ros = _ros(a)
            goal, pose = ros["goal_input"], ros["pose_input"]
            assert goal["refused"]["cdr"] == 2
            assert goal["refused"]["value"] == 1
            assert goal["refused"]["frame"] == 2
            assert goal["refused"]["size"] == 1
            assert goal["dropped_too_fast"] > 0
            wait_for(lambda: sum(_ros(a)["pose_input"]["refused"].values()) == 3, "pose refusals")
            assert pose["accepted"] == 0
            # the robot went nowhere but the flood's own goal (the start point)
            assert a.snapshot().goal_m == pytest.approx(START_M)
            # and the subscriptions are alive: a good goal still moves the robot
            session.put(goal_key, point("delta_base", [0.0, 0.02, -0.24]))  # stamped now
            wait_for(
                lambda: a.snapshot().goal_m == pytest.approx([0.0, 0.02, -0.24]),
                "a good goal after the bad ones",
                seen=lambda: _ros(a)["goal_input"],
            )
        finally:
            session.close()
            cleanup()


def test_through_a_ros_graphs_router_with_the_link_logged_in(tmp_path: Path) -> None:
    """The lab's layout: a Zenoh router (rmw_zenohd's part) that the ROS nodes connect to,
    the robot node's ROS side on a session of its own connected to it ([ros2] connect),
    the link behind its login; the peer with rmw_zenoh's scouting (gossip on)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = subprocess.Popen(
        [sys.executable, str(PEER.parent / "router.py"), endpoint],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert router.stdout is not None and router.stdout.readline().strip() == "router up"
        domain = random.randint(1, 200)
        env = {
            "DELTADASH_ROS2__DOMAIN_ID": str(domain),
            "DELTADASH_ROS2__CONNECT": json.dumps([endpoint]),
            "DELTADASH_LINK__USER": "lab",
            "DELTADASH_LINK__PASSWORD": "a-long-link-password",
        }
        with robot_node(tmp_path, **env):
            peer = Peer(endpoint, domain, ZENOH_CONFIG_OVERRIDE="scouting/multicast/enabled=false")
            try:
                peer.ask(op="subscribe", topic="/joint_states", type=JOINT_STATE)
                wait_for(lambda: len(peer.messages("/joint_states")) >= 10, "joint states")
            finally:
                peer.close()
            # the link's keys are not on the ROS graph's network
            seen: list[str] = []
            config = zenoh.Config()
            config.insert_json5("mode", '"peer"')
            config.insert_json5("scouting/multicast/enabled", "false")
            config.insert_json5("connect/endpoints", json.dumps([endpoint]))
            session = zenoh.open(config)
            try:
                session.declare_subscriber("deltadash/**", lambda s: seen.append(str(s.key_expr)))
                ros: list[str] = []
                session.declare_subscriber(f"{domain}/**", lambda s: ros.append(str(s.key_expr)))
                wait_for(lambda: len(ros) >= 50, "the ROS topics at a plain peer of the router")
                assert seen == []
            finally:
                session.close()
    finally:
        router.kill()
        router.wait()


def _api(server, method: str, path: str, body: dict | None, lease: str | None) -> Any:
    headers = {"Content-Type": "application/json", **({"X-Lease": lease} if lease else {})}
    request = urllib.request.Request(
        server.url + path,
        data=None if body is None else json.dumps(body).encode(),
        method=method,
        headers=headers,
    )
    with urllib.request.urlopen(request, timeout=15) as response:
        return json.load(response)


def test_the_goal_input_is_armed_for_one_lease_and_a_procedure_disarms_it(
    tmp_path: Path,
) -> None:
    """Through `deltadash serve --robot`: armed by the lease holder; disarmed when the lease
    is given back (a goal then moves nothing), or a calibration claims the robot."""
    env = {"DELTADASH_ROS2__GOAL_INPUT": "pose"}
    with (
        ros_robot(tmp_path, **env) as (node, peer, _),
        serve(tmp_path, DELTADASH_LINK__ROBOT=node.endpoint) as server,
    ):
        lease = server.post("/api/lease", {"client": "ros test"})["lease_id"]
        with pytest.raises(urllib.error.HTTPError) as refused:
            _api(server, "PUT", "/api/ros2/goals", {"enabled": True}, None)
        assert refused.value.code == 409  # without the lease
        armed = _api(server, "PUT", "/api/ros2/goals", {"enabled": True}, lease)
        assert armed["goal_input"]["armed"] is True
        wait_for(lambda: server.get("/api/ros2")["goal_input"]["armed"], "armed in the status")
        # the lease given back: disarmed by the station, a ROS goal then moves nothing
        _api(server, "DELETE", "/api/lease", None, lease)
        wait_for(
            lambda: (
                "lease" in (server.get("/api/ros2")["disarmed_because"] or "")
                and server.get("/api/ros2")["goal_input"]["armed"] is False
            ),
            "disarmed with the lease given back",
            seen=lambda: server.get("/api/ros2"),
        )
        goal_before = server.get("/api/status")["goal"]
        peer.ask(
            op="publish",
            topic="/delta/tip_goal",
            type=POSE,
            message=_goal("delta_base", [0.02, 0, -0.24]),
        )
        wait_for(
            lambda: server.get("/api/ros2")["goal_input"]["refused"].get("unarmed") == 1,
            "the goal refused, unarmed",
            seen=lambda: server.get("/api/ros2")["goal_input"],
        )
        assert server.get("/api/status")["goal"] == goal_before
        # armed again by a new lease; a calibration claims the robot: disarmed
        lease = server.post("/api/lease", {"client": "ros test"})["lease_id"]
        _rest(server, lease)
        _api(server, "PUT", "/api/ros2/goals", {"enabled": True}, lease)
        _api(server, "POST", "/api/calibration/run", {"poses": 12}, lease)
        wait_for(
            lambda: (
                "calibration" in (server.get("/api/ros2")["disarmed_because"] or "")
                and server.get("/api/ros2")["goal_input"]["armed"] is False
            ),
            "disarmed by the calibration",
            seen=lambda: server.get("/api/ros2"),
        )
        with pytest.raises(urllib.error.HTTPError) as refused:
            _api(server, "PUT", "/api/ros2/goals", {"enabled": True}, lease)
        assert refused.value.code == 409  # not while the calibration holds the robot


def _rest(server, lease: str) -> None:
    def torque() -> bool:
        try:
            _api(server, "POST", "/api/torque", {"enabled": True}, lease)
            return True
        except urllib.error.HTTPError:
            return False

    wait_for(torque, "torque on at rest")


@pytest.mark.parametrize("form", ["humble", "bridge"])
def test_humbles_keys_and_the_bridges(tmp_path: Path, form: str) -> None:
    """Humble's rmw_zenoh (TypeHashNotSupported in the keys): the SDK subscribes with it;
    zenoh-bridge-ros2dds's keys (the topic's name): a plain Zenoh subscriber reads them and
    mcap-ros2-support decodes the CDR."""
    env = (
        {"DELTADASH_ROS2__DISTRO": "humble"}
        if form == "humble"
        else {"DELTADASH_ROS2__FORM": "bridge"}
    )
    with ros_robot(tmp_path, **env) as (node, peer, domain):
        if form == "humble":
            found = peer.ask(
                op="subscribe",
                topic="/joint_states",
                type=JOINT_STATE,
                type_hash=graph.NO_HASH,
            )
            assert found["key"].endswith(
                "/sensor_msgs::msg::dds_::JointState_/TypeHashNotSupported"
            )
            wait_for(lambda: len(peer.messages("/joint_states")) >= 5, "Humble's joint states")
            return
        raw: list[zenoh.Sample] = []
        config, cleanup = zenoh_config(LinkSettings(), connect=node.endpoint)
        session = zenoh.open(config)
        try:
            session.declare_subscriber("joint_states", raw.append)
            wait_for(lambda: len(raw) >= 5, "the bridge's joint_states")
        finally:
            session.close()
            cleanup()
        message = decoder(JOINT_STATE)(raw[-1].payload.to_bytes())
        assert message.name == ["delta_joint_1", "delta_joint_2", "delta_joint_3"]
        assert raw[-1].attachment is None  # the bridge's form carries none

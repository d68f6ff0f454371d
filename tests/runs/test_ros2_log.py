"""Run logs as ROS 2 data (app/runs/ros2_log.py): a run's ``log.ros2.mcap`` is read by
two implementations that share nothing with the writer's encoder, the ``mcap`` reader with
mcap-ros2-support's decoder and ``rosbags`` opening it as a ROS 2 bag, and every message
is checked against the JSON log of the same tick (matched by log time) and against the
kinematics: the platform's frame is the FK of the logged joints."""

from __future__ import annotations

import json
import math
import shutil
import time
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader

from app.config import Settings, load_settings
from app.control.controller import Controller
from app.control.state import Fault, Snapshot
from app.runs.logs import COLUMNS, RunLog
from app.runs.manager import RunManager
from app.runs.recorder import row_of
from app.runs.trajectories import SinusoidParams
from app.server.backends import open_backend
from kinematics import THESIS_DELTA
from tests.support.sim_time import driving
from tests.support.wait import WAIT_S, wait_for

TOOL_M = (0.01, 0.0, -0.05)
HOME_M = np.array([0.01, 0.0, -0.27])  # the tip, 5 cm under the platform
SHORT = SinusoidParams(amplitude_m=(0.02, 0.02, 0.02), offset_m=(0.01, 0.0, -0.28), duration_s=1.0)
TYPES = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/delta/tip_pose": "geometry_msgs/msg/PoseStamped",
    "/delta/tip_pose_world": "geometry_msgs/msg/PoseStamped",
    "/delta/goal": "geometry_msgs/msg/PoseStamped",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}
PER_TICK = ("/joint_states", "/tf", "/delta/tip_pose", "/delta/goal")


def _ticks(path: Path) -> dict[int, dict[str, Any]]:
    """The JSON log's rows by log time [ns]."""
    with open(path, "rb") as file:
        return {m.log_time: json.loads(m.data) for _, _, m in make_reader(file).iter_messages()}


def _mcap_ros2(path: Path) -> dict[str, list[tuple[int, Any]]]:
    """Every message of the ROS 2 log, decoded by mcap-ros2-support: (log time, message)
    by topic; each channel's sequence numbers count from 0."""
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with open(path, "rb") as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages():
            assert message.publish_time == message.log_time
            assert message.sequence == len(out[channel.topic])
            out[channel.topic].append((message.log_time, decoded))
    return out


def _rosbags(path: Path) -> tuple[dict[str, list[tuple[int, Any]]], dict[str, int]]:
    """Every message as rosbags reads the file as a ROS 2 bag (the types from the file's
    own definitions): (log time, message) by topic, and the counts its index says."""
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with AnyReader([path]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert {c.ext.serialization_format for c in reader.connections} == {"cdr"}
        types = {c.topic: c.msgtype for c in reader.connections}
        assert sorted(types.values()) == sorted(TYPES.values())
        for connection, stamp, raw in reader.messages():
            out[connection.topic].append((stamp, reader.deserialize(raw, connection.msgtype)))
    return out, counts


def _ns(stamp: Any) -> int:
    return stamp.sec * 10**9 + stamp.nanosec


def _xyz(vector: Any) -> list[float]:
    return [vector.x, vector.y, vector.z]


def _check_messages(by_topic: dict[str, list[tuple[int, Any]]], ticks: dict, settings) -> None:
    """What both readers must find in the twin run's ROS 2 log (see the module doc)."""
    ros = settings.ros2
    counts = Counter({topic: len(messages) for topic, messages in by_topic.items()})
    assert {counts[t] for t in PER_TICK} == {len(ticks)}  # every tick, nothing dropped
    assert counts["/tf_static"] == 1 and counts["/delta/tip_pose_world"] == 0  # not holding
    first = min(ticks)
    (static_at, static), *_ = by_topic["/tf_static"]
    (mount,) = static.transforms
    assert static_at == first and _ns(mount.header.stamp) == first
    assert (mount.header.frame_id, mount.child_frame_id) == (ros.drone_frame, ros.base_frame)
    assert _xyz(mount.transform.translation) == list(settings.world.mount_position_m)
    joints = {}
    for stamp, message in by_topic["/joint_states"]:
        row = ticks[stamp]
        assert _ns(message.header.stamp) == stamp
        assert list(message.name) == list(ros.joint_names)
        assert list(message.position) == [row[f"measured_q{i}_rad"] for i in (1, 2, 3)]
        joints[stamp] = np.array(message.position)
    assert len(joints) == len(ticks)
    for stamp, message in by_topic["/tf"]:
        platform, tip = message.transforms
        assert _ns(platform.header.stamp) == _ns(tip.header.stamp) == stamp
        assert (platform.header.frame_id, platform.child_frame_id) == (
            ros.base_frame,
            ros.platform_frame,
        )
        assert (tip.header.frame_id, tip.child_frame_id) == (ros.platform_frame, ros.tip_frame)
        fk = THESIS_DELTA.fk(joints[stamp])  # the kinematics' own FK of the logged joints
        assert fk.ok
        assert _xyz(platform.transform.translation) == pytest.approx(fk.points, abs=1e-9)
        assert _xyz(tip.transform.translation) == list(TOOL_M)
        for frame in (platform, tip):  # a Delta's platform keeps the base's orientation
            rotation = frame.transform.rotation
            assert [rotation.x, rotation.y, rotation.z, rotation.w] == [0, 0, 0, 1]
    for topic, prefix in (("/delta/tip_pose", "measured"), ("/delta/goal", "goal")):
        for stamp, message in by_topic[topic]:
            row = ticks[stamp]
            assert _ns(message.header.stamp) == stamp and message.header.frame_id == ros.base_frame
            assert _xyz(message.pose.position) == [row[f"{prefix}_{a}_m"] for a in "xyz"]
    diagnostics = by_topic["/diagnostics"]
    times = [stamp for stamp, _ in diagnostics]
    assert times[0] == first and all(t in ticks for t in times)
    gaps = np.diff(times) / 1e9
    assert np.all((gaps >= 0.1 - 1e-9) & (gaps <= 0.1 + 0.005 + 1e-9)), gaps  # 10 Hz
    for stamp, message in diagnostics:
        (status,) = message.status
        values = {v.key: v.value for v in status.values}
        assert status.level == 0 and values["mode"] == ticks[stamp]["mode"]
        assert _ns(message.header.stamp) == stamp


@pytest.fixture(scope="module")
def twin_run(tmp_path_factory) -> tuple[RunLog, dict[int, dict], Settings]:
    """A short sinusoid run on the MuJoCo twin (simulated time), with a tool: its ticks'
    snapshots written the way the recorder writes them (row_of, the run's time), to a
    RunLog with the ROS 2 bag on. Returns the closed log, its JSON ticks and the settings."""
    folder = tmp_path_factory.mktemp("ros2_log")
    settings = load_settings(
        hardware={"backend": "sim"}, runs={"folder": str(folder)}, tool={"offset_m": TOOL_M}
    )
    with open_backend(settings, sim_time=True) as backend:
        clock = backend.sim_clock
        controller = Controller(
            settings,
            backend.bus,
            backend.kind,
            backend.description,
            clock=clock.now,
            tick_clock=clock,
        )
        controller.start()
        try:
            with driving(clock):
                log = _record(controller, folder)
        finally:
            controller.stop()
    return log, _ticks(log.mcap_path), settings


def _record(controller: Controller, folder: Path) -> RunLog:
    wait_for(lambda: _torque_on(controller), "torque on to be accepted")
    controller.set_goal(HOME_M).result(timeout=WAIT_S)
    wait_for(
        lambda: np.linalg.norm(controller.snapshot().point_measured_m - HOME_M) < 2e-3,
        "the tip at its start",
    )
    prepared = RunManager(controller, folder).prepare(SHORT, "sinusoid")
    log = RunLog(folder / "run", {"run_id": "twin"}, settings=controller.settings)
    seen: dict[str, Any] = {"t0": None, "ended": False}

    def on_tick(snap: Snapshot) -> None:  # as app/runs/recorder.py's Recorder.on_tick
        active = controller.current_source is prepared.source
        if seen["t0"] is None and not active:
            return
        if not active:
            controller.remove_listener(on_tick)
            seen["ended"] = True
            return
        if seen["t0"] is None:
            seen["t0"] = snap.time_s
            log.start_ns = time.time_ns()
        log.write(row_of(snap, snap.time_s - seen["t0"]), snap)

    controller.add_listener(on_tick)
    started = controller.run_source(prepared.source, prepared.start_m, 0.002, prepared.model)
    started.result(timeout=WAIT_S)
    wait_for(lambda: seen["ended"], "the run to end")
    log.close()
    return log


def _torque_on(controller: Controller) -> bool:
    """Torque on; False while it is refused (the hanging arm outside its joint limits)."""
    try:
        controller.set_torque(True).result(timeout=WAIT_S)
    except Exception:
        return False
    return True


@pytest.mark.slow  # a run on the twin
def test_the_mcap_reader_with_the_ros2_decoder_reads_every_channel_as_the_json_log(twin_run):
    log, ticks, settings = twin_run
    assert len(ticks) > 200  # approach, 1 s timed, stop
    with open(log.ros2_path, "rb") as file:
        reader = make_reader(file)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
    assert {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()} == TYPES
    by_topic = _mcap_ros2(log.ros2_path)
    _check_messages(by_topic, ticks, settings)
    counts = summary.statistics.channel_message_counts
    assert sum(counts.values()) == sum(len(m) for m in by_topic.values())


@pytest.mark.slow  # a run on the twin
def test_rosbags_opens_the_run_as_a_ros2_bag_with_the_same_messages(twin_run):
    log, ticks, settings = twin_run
    by_topic, counts = _rosbags(log.ros2_path)  # the bare file: no metadata.yaml needed
    _check_messages(by_topic, ticks, settings)
    assert counts == {topic: len(by_topic.get(topic, [])) for topic in TYPES}
    assert counts == {t: len(m) for t, m in _mcap_ros2(log.ros2_path).items()} | {
        "/delta/tip_pose_world": 0
    }
    with Reader(log.ros2_path) as reader:  # rosbags' rosbag2 reader, the same file
        assert reader.message_count == sum(counts.values())
        assert reader.start_time == min(ticks) and reader.end_time == max(ticks) + 1


# without the twin: snapshots made up, for what a short run does not show


def _snap(k: int, **fields: Any) -> Snapshot:
    q = THESIS_DELTA.ik(np.array([0.0, 0.0, -0.22])).joints + 0.001 * k
    platform = THESIS_DELTA.fk(q).points
    values: dict[str, Any] = {
        "time_s": k * 0.005,
        "tick": k,
        "mode": "test",
        "torque": True,
        "joints_measured_rad": q,
        "platform_measured_m": platform,
        "point_measured_m": platform,
        "goal_m": platform,
    }
    return Snapshot(**(values | fields))


def _row(snap: Snapshot) -> dict[str, Any]:
    row = dict.fromkeys(COLUMNS)
    row.update({"t_s": snap.time_s, "phase": "timed", "mode": snap.mode, "faults": ""})
    return row


def _write(log: RunLog, snaps: list[Snapshot]) -> None:
    for snap in snaps:
        log.write(_row(snap), snap)


def test_no_ros2_bag_without_the_settings_or_with_it_off(tmp_path):
    plain = RunLog(tmp_path / "plain", {"run_id": "x"})
    off = RunLog(tmp_path / "off", {"run_id": "y"}, settings=load_settings(ros2={"run_log": False}))
    for log in (plain, off):
        _write(log, [_snap(0)])
        log.close()
        assert log.ros2_path is None and sorted(p.name for p in log.mcap_path.parent.iterdir()) == [
            "log.csv",
            "log.mcap",
        ]


def test_a_crash_leaves_a_bag_both_readers_open_up_to_the_last_commit(tmp_path):
    """Holding in the world, a fault, ticks before the first read; a wrist; a namespace."""
    settings = load_settings(
        ros2={"namespace": "/lab", "distro": "humble"}, wrist={"enabled": True, "servo_id": 4}
    )
    log = RunLog(tmp_path / "run", {"run_id": "x"}, settings=settings)
    log.start_ns = 1_800_000_000 * 10**9 + 7
    nan3 = np.full(3, np.nan)
    holding = {"extra": {"measured_world_m": [1.0, 2.0, 3.0], "measured_heading_world_rad": 0.5}}
    fault = (Fault("servo", "overload", servo_id=2),)
    snaps = [_snap(k, platform_measured_m=nan3, point_measured_m=nan3, goal_m=nan3) for k in (0, 1)]
    snaps += [_snap(k, phi_measured_rad=0.2, **holding) for k in range(2, 30)]
    snaps += [_snap(30, faults=fault, phi_measured_rad=0.2)]
    _write(log, snaps)
    log._flush()  # a commit: what a process killed now leaves
    crashed = tmp_path / "crashed.mcap"
    shutil.copy(log.ros2_path, crashed)
    _write(log, [_snap(31)])
    log.close()
    by_topic = _mcap_ros2(crashed)
    ros_bag, counts = _rosbags(crashed)
    assert {t: len(m) for t, m in by_topic.items()} == {t: n for t, n in counts.items() if n}
    assert {t: len(m) for t, m in ros_bag.items()} == {t: len(m) for t, m in by_topic.items()}
    stamps = [log.start_ns + round(s.time_s * 1e9) for s in snaps]
    assert [t for t, _ in by_topic["/lab/joint_states"]] == stamps
    names = [*settings.ros2.joint_names, settings.ros2.wrist_joint_name]
    assert all(list(m.name) == names for _, m in by_topic["/lab/joint_states"])
    assert [t for t, _ in by_topic["/lab/delta/tip_pose_world"]] == stamps[2:30]
    (_, world), *_ = by_topic["/lab/delta/tip_pose_world"]
    assert _xyz(world.pose.position) == [1.0, 2.0, 3.0] and world.header.frame_id == "map"
    assert world.pose.orientation.z == pytest.approx(math.sin(0.25))
    for topic in ("/tf", "/lab/delta/tip_pose", "/lab/delta/goal"):  # from the first read
        assert [t for t, _ in by_topic[topic]] == stamps[2:], topic
    (_, tf), *_ = by_topic["/tf"]
    assert tf.transforms[1].transform.rotation.z == pytest.approx(math.sin(0.1))  # the wrist
    levels = [(t, m.status[0].level) for t, m in by_topic["/lab/diagnostics"]]
    assert levels == [(stamps[0], 0), (stamps[20], 0), (stamps[30], 2)]  # 10 Hz; the fault
    with open(log.ros2_path, "rb") as file:  # humble: no type hashes in the channels
        channels = make_reader(file).get_summary().channels.values()
    assert all("topic_type_hash" not in c.metadata for c in channels)
    assert {c.metadata["offered_qos_profiles"].count("durability: 1") for c in channels} == {0, 1}


def test_a_tick_that_cannot_be_written_as_ros2_costs_the_json_log_nothing(
    tmp_path, monkeypatch, caplog
):
    log = RunLog(tmp_path / "run", {"run_id": "x"}, settings=load_settings())

    def broken(snap: Snapshot, stamp_ns: int) -> None:
        raise ValueError("no message for this")

    monkeypatch.setattr(log._ros2, "write", broken)
    _write(log, [_snap(k) for k in range(5)])
    log.close()
    assert [t["t_s"] for t in _ticks(log.mcap_path).values()] == [k * 0.005 for k in range(5)]
    assert _mcap_ros2(log.ros2_path) == {}  # a complete file, without messages
    assert caplog.text.count("could not be written as ROS 2 messages") == 1

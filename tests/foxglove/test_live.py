"""The Foxglove live server end to end: a plain WebSocket client speaking foxglove.sdk.v1
(tests/foxglove/client.py) subscribes to every channel of a running app and decodes each
message on its own, checked against the robot's state."""

from __future__ import annotations

import numpy as np
import pytest

from app.foxglove import messages
from tests.foxglove.client import SUBPROTOCOL, FoxgloveClient, Received
from tests.foxglove.conftest import TOOL_OFFSET_M
from tests.support.app_client import cleared, settle_at, torque_on
from tests.support.wait import ok_json, wait_for

pytestmark = pytest.mark.slow  # an app, a settle on the emulated bus, a run: seconds

TIP_GOAL_M = (0.01, -0.005, -0.255)
ENCODINGS = {  # topic -> (message encoding, schema name)
    messages.TF: ("protobuf", "foxglove.FrameTransforms"),
    messages.JOINT_STATES: ("protobuf", "foxglove.JointStates"),
    messages.LOG: ("protobuf", "foxglove.Log"),
    messages.RUNS: ("protobuf", "foxglove.Event"),
    messages.TRACKING: ("json", "deltadash.Tracking"),
    messages.LOOP: ("json", "deltadash.LoopHealth"),
}
GENTLE_SINE = {  # about the settled tip (the tool's offset lifts the platform)
    "amplitude_m": [0.01, 0.01, 0.0],
    "frequency_hz": [0.5, 0.5, 0.0],
    "offset_m": list(TIP_GOAL_M),
    "duration_s": 20,
}
PERIODIC = {messages.TF, messages.JOINT_STATES, messages.TRACKING, messages.LOOP}
LOG_ERROR, LOG_INFO, LOG_WARNING = 4, 2, 3  # foxglove.Log.Level


def _xyz(value: dict | None) -> np.ndarray:
    assert value is not None
    return np.array([value[axis] for axis in "xyz"], dtype=float)


def _stamp_ns(stamp: dict) -> int:
    return stamp["seconds"] * 1_000_000_000 + stamp["nanos"]  # google.protobuf.Timestamp


def _one_look(fox: FoxgloveClient) -> dict[str, Received]:
    """The latest log time at which every periodic channel sent a message (one tick,
    sent together), and those messages."""
    times = [{r.log_time_ns: r for r in fox.messages(topic)} for topic in sorted(PERIODIC)]
    common = set.intersection(*(set(t) for t in times))
    assert common, "no tick sent on every periodic channel"
    latest = max(common)
    return {topic: t[latest] for topic, t in zip(sorted(PERIODIC), times, strict=True)}


def test_every_channel_is_advertised_subscribed_and_decoded(app_client, url):
    settings = app_client.app.state.settings
    ros = settings.ros2
    settle_at(app_client, TIP_GOAL_M)
    with FoxgloveClient(url) as fox:
        assert fox.ws.subprotocol == SUBPROTOCOL
        advertised = fox.wait_advertised(set(messages.TOPICS))
        assert fox.server_info is not None and fox.server_info["name"] == "deltadash"
        for topic, (encoding, schema_name) in ENCODINGS.items():
            channel = advertised[topic]
            assert (channel["encoding"], channel["schemaName"]) == (encoding, schema_name)
        fox.subscribe(set(messages.TOPICS))
        wait_for(
            lambda: all(len(fox.messages(t)) >= 3 for t in PERIODIC),
            "three messages on every periodic channel",
            seen=lambda: ({t: len(fox.messages(t)) for t in PERIODIC}, fox.errors),
        )
        assert not fox.errors, fox.errors
        look = _one_look(fox)
        snap = app_client.app.state.controller.snapshot()  # the robot at rest, as it is now

    # the frames: drone -> base (mount) -> platform -> tip, base -> goal, stamped as sent
    tf = look[messages.TF]
    by_child = {t["child_frame_id"]: t for t in tf.message["transforms"]}
    assert set(by_child) == {
        ros.base_frame,
        ros.platform_frame,
        ros.tip_frame,
        settings.foxglove.goal_frame,
    }
    parents = {child: t["parent_frame_id"] for child, t in by_child.items()}
    assert parents == {
        ros.base_frame: ros.drone_frame,
        ros.platform_frame: ros.base_frame,
        ros.tip_frame: ros.platform_frame,
        settings.foxglove.goal_frame: ros.base_frame,
    }
    for transform in by_child.values():
        assert _stamp_ns(transform["timestamp"]) == tf.log_time_ns
    platform = _xyz(by_child[ros.platform_frame]["translation"])
    tip_offset = _xyz(by_child[ros.tip_frame]["translation"])
    goal = _xyz(by_child[settings.foxglove.goal_frame]["translation"])
    rotation = by_child[ros.platform_frame]["rotation"]
    assert (rotation["x"], rotation["y"], rotation["z"], rotation["w"]) == (0, 0, 0, 1)
    np.testing.assert_allclose(tip_offset, TOOL_OFFSET_M, atol=1e-12)
    np.testing.assert_allclose(goal, TIP_GOAL_M, atol=1e-9)
    mount = by_child[ros.base_frame]  # the base in the drone's body, from [world]
    np.testing.assert_allclose(_xyz(mount["translation"]), settings.world.mount_position_m)
    turn = mount["rotation"]
    wxyz = (turn["w"], turn["x"], turn["y"], turn["z"])
    np.testing.assert_allclose(wxyz, settings.world.mount_quaternion, atol=1e-15)
    # against the robot: at rest, the measured platform and the tip are where it says
    np.testing.assert_allclose(platform, snap.platform_measured_m, atol=1e-4)
    np.testing.assert_allclose(platform + tip_offset, snap.point_measured_m, atol=1e-4)
    np.testing.assert_allclose(platform + tip_offset, TIP_GOAL_M, atol=3e-3)

    # the tracking error of the same tick: commanded - measured, from the same snapshot
    tracking = look[messages.TRACKING].message
    measured, commanded = _xyz(tracking["measured_m"]), _xyz(tracking["commanded_m"])
    np.testing.assert_allclose(_xyz(tracking["platform_m"]), platform, atol=1e-15)
    np.testing.assert_allclose(measured, platform + tip_offset, atol=1e-12)
    np.testing.assert_allclose(_xyz(tracking["goal_m"]), goal, atol=1e-15)
    error = _xyz(tracking["error_m"])
    np.testing.assert_allclose(error, commanded - measured, atol=1e-12)
    np.testing.assert_allclose(_xyz(tracking["error_mm"]), error * 1e3, atol=1e-9)
    assert tracking["error_norm_mm"] == pytest.approx(np.linalg.norm(error) * 1e3, abs=1e-9)
    np.testing.assert_allclose(commanded, TIP_GOAL_M, atol=1e-6)  # the approach is done
    np.testing.assert_allclose(error, snap.shown_error_m, atol=1e-4)
    assert tracking["tick"] <= snap.tick and tracking["mode"] == snap.mode

    # the joints of the same tick, named as ROS names them
    joints = look[messages.JOINT_STATES].message
    assert _stamp_ns(joints["timestamp"]) == look[messages.JOINT_STATES].log_time_ns
    assert [j["name"] for j in joints["joints"]] == list(ros.joint_names)
    positions = [j["position"] for j in joints["joints"]]
    assert all("position" in j["__present__"] for j in joints["joints"])
    np.testing.assert_allclose(positions, snap.joints_measured_rad, atol=2e-3)

    # the loop's health, of the same tick
    loop = look[messages.LOOP].message
    assert loop["tick"] == tracking["tick"]
    assert loop["target_hz"] == settings.loop.rate_hz
    assert loop["rate_hz"] is not None and loop["rate_hz"] > 0
    assert loop["lateness_p99_ms"] is not None and loop["lateness_p99_ms"] >= 0
    assert loop["overruns_10s"] >= 0 and loop["health"] in messages.HEALTH_LEVELS
    assert loop["health_level"] == messages.HEALTH_LEVELS[loop["health"]]
    assert loop["torque"] is True and loop["estopped"] is False and loop["faults"] == 0
    ticks = [r.message["tick"] for r in fox.messages(messages.LOOP)]
    assert ticks == sorted(ticks) and len(set(ticks)) == len(ticks)  # each tick once


def test_a_fault_and_its_reset_are_logged(app_client, url):
    fresh = cleared(app_client)
    emulator = app_client.app.state.backend.emulator
    torque_on(fresh)
    with FoxgloveClient(url) as fox:
        fox.subscribe({messages.LOG})
        try:
            emulator.raise_hardware_error(1, 1 << 5)  # overload: servo 1 shuts down
            wait_for(lambda: ok_json(fresh.get("/api/status"))["mode"] == "fault", "the fault")
            fault = fox.wait_message(
                messages.LOG,
                lambda m: m["level"] == LOG_ERROR and "hardware error overload" in m["message"],
                "the fault as an error in the log",
            )
        finally:
            emulator.clear_faults()
        assert fault.message["name"] == "deltadash"
        assert "servo 1" in fault.message["message"]
        assert _stamp_ns(fault.message["timestamp"]) == fault.log_time_ns
        ok_json(fresh.post("/api/reset"))
        fox.wait_message(
            messages.LOG,
            lambda m: m["level"] == LOG_INFO and m["message"] == "faults cleared",
            "the reset in the log",
        )
        fresh.post("/api/estop")
        fox.wait_message(
            messages.LOG,
            lambda m: m["level"] == LOG_ERROR and m["message"] == "e-stop",
            "the e-stop in the log",
        )
        ok_json(fresh.post("/api/reset"))


def test_a_runs_start_and_end_are_events(app_client, url):
    fresh = cleared(app_client)
    settle_at(fresh, TIP_GOAL_M)  # a run starts from a robot at rest
    with FoxgloveClient(url) as fox:
        fox.subscribe({messages.RUNS, messages.LOG})
        run_id = ok_json(fresh.post("/api/tests/sinusoid", json=GENTLE_SINE))["run_id"]

        def meta(message: dict) -> dict[str, str]:
            return {pair["key"]: pair["value"] for pair in message["metadata"]}

        start = fox.wait_message(
            messages.RUNS,
            lambda m: meta(m).get("event") == "run start" and meta(m)["run_id"] == run_id,
            "the run's start as an event",
        )
        assert meta(start.message)["kind"] == "sinusoid"
        assert start.message["start_time"] == start.message["end_time"]
        ok_json(fresh.post(f"/api/runs/{run_id}/abort"))
        end = fox.wait_message(
            messages.RUNS,
            lambda m: meta(m).get("event") == "run end" and meta(m)["run_id"] == run_id,
            "the run's end as an event",
        )
        run = ok_json(fresh.get(f"/api/runs/{run_id}"))
        assert meta(end.message)["state"] == run["state"] == "aborted"
        assert "operator" in meta(end.message)["reason"]
        assert end.message["start_time"] == start.message["start_time"]
        started_ns, ended_ns = (_stamp_ns(end.message[k]) for k in ("start_time", "end_time"))
        assert started_ns == pytest.approx(run["started_at"] * 1e9, abs=1e3)
        assert ended_ns == pytest.approx(run["ended_at"] * 1e9, abs=1e3)
        assert ended_ns > started_ns
        lines = [m.message for m in fox.messages(messages.LOG)]
        assert any(m["message"] == f"run {run_id} (sinusoid) started" for m in lines)
        fox.wait_message(
            messages.LOG,
            lambda m: (
                m["level"] == LOG_WARNING
                and m["message"].startswith(f"run {run_id} ")
                and "aborted" in m["message"]
            ),
            "the run's end in the log",
        )

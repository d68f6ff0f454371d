"""The channels' messages from snapshots, without a server: what an unknown value becomes,
that the frames agree with the ROS 2 topics', what the log says as the state changes,
and which runs are news. Protobuf messages are read back with their own schema
(tests/foxglove/protobuf.py), as a client would."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from foxglove.messages import FrameTransforms, JointStates, LogLevel

from app.config import load_settings
from app.control.state import ContactReading, Fault, Snapshot
from app.foxglove import messages
from app.foxglove.live import RunWatch
from app.ros2.messages import Messages
from kinematics.tool import Tool
from tests.foxglove import protobuf

STAMP_NS = 1_796_000_000_123_456_789


def _decode(message, kind) -> dict:
    schema = kind.get_schema()
    assert schema.encoding == "protobuf"
    types = protobuf.descriptor_types(schema.data)
    return protobuf.decode(types, schema.name, message.encode())


def _by_child(message: FrameTransforms) -> dict[str, dict]:
    return {t["child_frame_id"]: t for t in _decode(message, FrameTransforms)["transforms"]}


def _moving(**changes) -> Snapshot:
    platform = np.array([0.01, -0.02, -0.23])
    return replace(
        Snapshot(
            tick=42,
            mode="jog",
            torque=True,
            joints_measured_rad=np.array([0.5, 0.6, 0.7]),
            platform_measured_m=platform,
            point_measured_m=platform + [0.0, 0.0, -0.03],
            point_commanded_m=platform + [0.001, 0.0, -0.03],
            goal_m=np.array([0.02, -0.02, -0.26]),
        ),
        **changes,
    )


def test_nothing_known_yet_is_null_or_left_out():
    settings = load_settings()
    snap = Snapshot()  # before the first read: every position NaN
    builder = messages.Builder(settings)
    frames = _by_child(builder.transforms(snap, STAMP_NS))
    assert set(frames) == {settings.ros2.base_frame}  # only the mount: nothing to place
    tracking = messages.tracking(snap)
    json.dumps(tracking, allow_nan=False)  # strict JSON: no NaN anywhere
    json.dumps(messages.loop_health(snap), allow_nan=False)
    assert tracking["measured_m"] is None and tracking["error_m"] is None
    assert tracking["error_norm_mm"] is None
    joints = _decode(builder.joint_states(snap, STAMP_NS), JointStates)["joints"]
    assert [j["name"] for j in joints] == list(settings.ros2.joint_names)
    assert all("position" not in j["__present__"] for j in joints)  # unset, not 0


def test_the_error_is_null_without_a_setpoint_and_the_frames_still_drawn():
    snap = _moving(torque=False)  # a relaxed arm: commanded - measured is stale
    tracking = messages.tracking(snap)
    assert tracking["error_m"] is None and tracking["error_norm_mm"] is None
    assert tracking["measured_m"] == {"x": 0.01, "y": -0.02, "z": pytest.approx(-0.26)}
    on = messages.tracking(_moving())
    assert on["error_mm"]["x"] == pytest.approx(1.0) and on["error_norm_mm"] == pytest.approx(1.0)


def test_the_tracking_carries_the_contact_estimate_only_while_valid():
    assert messages.tracking(Snapshot())["contact_force_n"] is None
    reading = ContactReading(np.array([0.5, 0.0, -2.0]), np.array([0.1, 0.1, 0.2]), True, None)
    tracking = messages.tracking(replace(Snapshot(), contact=reading))
    json.dumps(tracking, allow_nan=False)
    assert tracking["contact_force_n"] == {"x": 0.5, "y": 0.0, "z": -2.0}
    assert tracking["contact_std_n"]["z"] == 0.2 and tracking["contact_valid"] is True
    assert set(tracking) <= set(messages.TRACKING_SCHEMA["properties"])


@pytest.mark.parametrize("phi", [0.0, 0.7])
def test_the_frames_are_the_ros2_topics_frames(phi):
    settings = load_settings(tool={"offset_m": [0.02, 0.0, -0.03]}, wrist={"enabled": True})
    snap = _moving(phi_measured_rad=phi, phi_goal_rad=-0.4)
    ours = _by_child(messages.Builder(settings).transforms(snap, STAMP_NS))
    ros = Messages(settings).tf(snap, STAMP_NS / 1e9)
    assert ros is not None
    for theirs in ros.transforms:
        mine = ours[theirs.child_frame_id]
        assert mine["parent_frame_id"] == theirs.header.frame_id
        t, r = theirs.transform.translation, theirs.transform.rotation
        np.testing.assert_allclose(
            [mine["translation"][k] for k in "xyz"], [t.x, t.y, t.z], atol=1e-15
        )
        np.testing.assert_allclose(
            [mine["rotation"][k] for k in "xyzw"], [r.x, r.y, r.z, r.w], atol=1e-15
        )
    # and the tip where the kinematics put it: platform + Rz(phi) d
    tip = Tool(settings.tool.offset_m, wrist=True).tip(snap.platform_measured_m, phi)
    drawn = [ours[settings.ros2.platform_frame]["translation"][k] for k in "xyz"]
    drawn = np.add(drawn, [ours[settings.ros2.tip_frame]["translation"][k] for k in "xyz"])
    np.testing.assert_allclose(drawn, tip, atol=1e-15)
    goal = ours[settings.foxglove.goal_frame]
    assert goal["parent_frame_id"] == settings.ros2.base_frame
    assert [goal["translation"][k] for k in "xyz"] == [0.02, -0.02, -0.26]
    assert goal["rotation"]["z"] == pytest.approx(math.sin(-0.2))  # the wrist's goal
    assert goal["timestamp"] == {
        "seconds": STAMP_NS // 10**9,
        "nanos": STAMP_NS % 10**9,
        "__present__": ["seconds", "nanos"],
    }
    joints = _decode(messages.Builder(settings).joint_states(snap, STAMP_NS), JointStates)
    names = [j["name"] for j in joints["joints"]]
    assert names == [*settings.ros2.joint_names, settings.ros2.wrist_joint_name]
    assert [j["position"] for j in joints["joints"]] == [0.5, 0.6, 0.7, phi]


def test_the_log_says_what_changed_once():
    state_log = messages.StateLog()
    quiet = _moving()
    fault = Fault("servo", "servo 1: hardware error overload", servo_id=1, kind="hw")
    assert state_log.changes(quiet) == []
    faulted = replace(quiet, faults=(fault,), mode="fault")
    assert state_log.changes(faulted) == [
        (LogLevel.Error, "fault: servo 1: hardware error overload (servo, servo 1)")
    ]
    assert state_log.changes(faulted) == []  # the same fault, the same count: no news
    again = replace(faulted, faults=(fault.again(fault),))
    assert state_log.changes(again) == [
        (LogLevel.Error, "fault: servo 1: hardware error overload (servo, servo 1, seen 2 times)")
    ]
    stopped = replace(quiet, estopped=True, warning="held by e-stop")
    assert state_log.changes(stopped) == [
        (LogLevel.Error, "e-stop"),
        (LogLevel.Info, "faults cleared"),
        (LogLevel.Warning, "warning: held by e-stop"),
    ]
    assert state_log.changes(quiet) == [(LogLevel.Info, "e-stop reset")]


def _run(run_id: str, state: str = "running", started_at: float = 100.0) -> SimpleNamespace:
    return SimpleNamespace(
        run_id=run_id,
        kind="step",
        state=state,
        reason=None,
        started_at=started_at,
        ended_at=None,
        samples=0,
    )


def test_runs_start_and_end_once_and_old_runs_are_no_news():
    old = _run("old", "done", 1.0)
    listed = [old]
    manager = SimpleNamespace(list=lambda: sorted(listed, key=lambda r: -r.started_at))
    watch = RunWatch(lambda: manager)
    assert watch.changes() == []
    new = _run("new")
    listed.append(new)
    assert watch.changes() == [(new, False)]
    assert watch.changes() == []
    new.state, new.reason, new.ended_at = "aborted", "e-stop", 103.5
    quick = _run("quick", "done", 200.0)  # over before it was seen: both at once
    listed.append(quick)
    assert watch.changes() == [(new, True), (quick, False), (quick, True)]
    assert watch.changes() == []
    event = messages.run_event(new, True, STAMP_NS)
    decoded = _decode(event, type(event))
    assert decoded["start_time"]["seconds"] == 100 and decoded["end_time"]["seconds"] == 103
    assert decoded["end_time"]["nanos"] == 500_000_000
    meta = {p["key"]: p["value"] for p in decoded["metadata"]}
    assert meta == {
        "event": "run end",
        "run_id": "new",
        "kind": "step",
        "state": "aborted",
        "reason": "e-stop",
        "samples": "0",
    }
    assert messages.run_text(new, True) == (LogLevel.Warning, "run new (step) aborted: e-stop")
    assert RunWatch(lambda: None).changes() == []  # before the run manager exists

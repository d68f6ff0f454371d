"""deltadash's ROS 2 messages and names against independent implementations: type hashes
computed by zenoh-ros2-sdk from the peer's own definitions, CDR decoded by
mcap-ros2-support, attachments and QoS read by the SDK, and the tf chain against the
kinematics' tool."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from zenoh_ros2_sdk.attachment import Attachment
from zenoh_ros2_sdk.message_registry import MessageRegistry
from zenoh_ros2_sdk.qos import QosDurability, QosProfile, QosReliability
from zenoh_ros2_sdk.utils import get_type_hash, load_dependencies_recursive

from app.config import Settings
from app.control.state import ContactReading, Fault, Snapshot
from app.ros2 import graph
from app.ros2.messages import (
    DIAGNOSTICS,
    JOINT_STATE,
    ODOMETRY,
    POINT,
    POSE,
    PX4_ODOMETRY,
    TF,
    WRENCH,
    Messages,
    type_hash,
)
from kinematics import THESIS_DELTA
from kinematics.tool import Tool
from tests.ros2.definitions import MSG, decoder, text

TYPES = [JOINT_STATE, TF, POSE, POINT, DIAGNOSTICS, ODOMETRY, PX4_ODOMETRY, WRENCH]


@pytest.mark.parametrize("typename", TYPES)
def test_type_hashes_agree_with_an_independent_computation(typename: str) -> None:
    registry = MessageRegistry(str(MSG))
    definition = text(typename)
    theirs = get_type_hash(
        typename,
        msg_definition=definition,
        dependencies=load_dependencies_recursive(typename, definition, registry),
    )
    assert type_hash("jazzy", typename) == theirs


def _snapshot(phi: float = 0.4, estopped: bool = False) -> tuple[Snapshot, np.ndarray]:
    joints = np.array([0.35, 0.5, 0.62])
    platform = THESIS_DELTA.fk(joints).points
    tool = Tool(offset_m=(0.01, 0.0, -0.03), wrist=True)
    tip = tool.tip(platform, phi)
    snap = Snapshot(
        tick=7,
        mode="jog",
        torque=True,
        estopped=estopped,
        joints_measured_rad=joints,
        platform_measured_m=platform,
        point_measured_m=tip,
        phi_measured_rad=phi,
        extra={"measured_world_m": [1.0, 2.0, 0.5], "measured_heading_world_rad": 0.25},
    )
    return snap, tip


@pytest.fixture
def messages() -> Messages:
    settings = Settings(tool={"offset_m": (0.01, 0.0, -0.03)}, wrist={"enabled": True})
    return Messages(settings)


def _decode(messages: Messages, message, typename: str):
    return decoder(typename)(messages.cdr(message, typename))


def test_joint_states_decode_with_a_second_cdr_reader(messages: Messages) -> None:
    snap, _ = _snapshot()
    out = _decode(messages, messages.joint_state(snap, 1234.25), JOINT_STATE)
    assert (out.header.stamp.sec, out.header.stamp.nanosec) == (1234, 250_000_000)
    assert out.name == ["delta_joint_1", "delta_joint_2", "delta_joint_3", "delta_wrist"]
    assert out.position[:3] == pytest.approx(snap.joints_measured_rad.tolist())
    assert out.position[3] == pytest.approx(0.4)


def test_the_tf_chain_composes_to_the_tool_tip(messages: Messages) -> None:
    snap, tip = _snapshot(phi=0.4)
    out = _decode(messages, messages.tf(snap, 10.0), TF)
    platform, tool = out.transforms
    assert (platform.header.frame_id, platform.child_frame_id) == ("delta_base", "delta_platform")
    assert (tool.header.frame_id, tool.child_frame_id) == ("delta_platform", "delta_tip")
    t = platform.transform.translation
    at = np.array([t.x, t.y, t.z])
    assert at == pytest.approx(THESIS_DELTA.fk(snap.joints_measured_rad).points, abs=1e-12)
    q = platform.transform.rotation
    assert (q.w, q.x, q.y, q.z) == (1.0, 0.0, 0.0, 0.0)  # a Delta's platform does not turn
    o = tool.transform.translation
    assert at + np.array([o.x, o.y, o.z]) == pytest.approx(tip, abs=1e-12)
    r = tool.transform.rotation
    assert 2 * math.atan2(r.z, r.w) == pytest.approx(0.4)


def test_the_tip_poses_in_the_base_and_the_world(messages: Messages) -> None:
    snap, tip = _snapshot(phi=-0.3)
    base = _decode(messages, messages.tip_pose(snap, 5.0), POSE)
    p = base.pose.position
    assert base.header.frame_id == "delta_base"
    assert [p.x, p.y, p.z] == pytest.approx(tip.tolist())
    world = _decode(messages, messages.tip_world(snap, 5.0), POSE)
    p, q = world.pose.position, world.pose.orientation
    assert world.header.frame_id == "map"
    assert [p.x, p.y, p.z] == [1.0, 2.0, 0.5]
    assert 2 * math.atan2(q.z, q.w) == pytest.approx(0.25)
    assert messages.tip_world(Snapshot(), 5.0) is None  # not holding: nothing to say


def test_the_tip_wrench_is_the_contact_estimate_in_the_base_frame(messages: Messages) -> None:
    snap = dataclasses.replace(
        Snapshot(),
        contact=ContactReading(np.array([0.25, -1.5, -2.0]), np.full(3, 0.1), True, None),
    )
    out = _decode(messages, messages.tip_wrench(snap, 7.25), WRENCH)
    assert out.header.frame_id == "delta_base"
    assert (out.header.stamp.sec, out.header.stamp.nanosec) == (7, 250_000_000)
    f, t = out.wrench.force, out.wrench.torque
    assert [f.x, f.y, f.z] == [0.25, -1.5, -2.0]
    assert [t.x, t.y, t.z] == [0.0, 0.0, 0.0]
    assert messages.tip_wrench(Snapshot(), 7.0) is None  # no valid estimate: nothing sent


def test_diagnostics_say_error_on_an_e_stop_and_name_the_fault(messages: Messages) -> None:
    snap, _ = _snapshot(estopped=True)
    out = _decode(
        messages, messages.diagnostics(snap, 1.0, {"goal input refused": "3"}), DIAGNOSTICS
    )
    (status,) = out.status
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == 2 and status.message == "e-stop"
    assert values["estopped"] == "true" and values["goal input refused"] == "3"
    calm, _ = _snapshot()
    (status,) = _decode(messages, messages.diagnostics(calm, 1.0), DIAGNOSTICS).status
    assert status.level == 0 and status.message == "jog"
    faulted = Snapshot(faults=(Fault("following", "following error 12 mm on joint 2"),))
    (status,) = _decode(messages, messages.diagnostics(faulted, 1.0), DIAGNOSTICS).status
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == 2 and status.message == "following error 12 mm on joint 2"
    assert values["faults"] == "following error 12 mm on joint 2"


def test_tf_static_carries_the_mount_from_the_config() -> None:
    settings = Settings(world={"mount_position_m": (0.01, -0.02, -0.1)})
    messages = Messages(settings)
    (mount,) = _decode(messages, messages.tf_static(3.0), TF).transforms
    assert (mount.header.frame_id, mount.child_frame_id) == ("base_link", "delta_base")
    t = mount.transform.translation
    assert [t.x, t.y, t.z] == [0.01, -0.02, -0.1]


def test_attachments_read_by_the_sdk() -> None:
    gid = graph.new_gid()
    data = graph.attachment(41, 1_796_000_000_123_456_789, gid)
    theirs = Attachment.from_bytes(data)
    assert (theirs.sequence_id, theirs.timestamp_ns, theirs.gid) == (
        41,
        1_796_000_000_123_456_789,
        gid,
    )
    assert graph.read_attachment(theirs.to_bytes()) == (41, 1_796_000_000_123_456_789, gid)
    with pytest.raises(ValueError, match="attachment"):
        graph.read_attachment(data[:20])


@pytest.mark.parametrize(
    ("ours", "theirs"),
    [
        (graph.encode_qos(), QosProfile()),
        (graph.encode_qos(reliable=False), QosProfile(reliability=QosReliability.BEST_EFFORT)),
        (
            graph.encode_qos(transient_local=True, depth=1),
            QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=1),
        ),
    ],
)
def test_qos_in_tokens_as_the_sdk_encodes_it(ours: str, theirs: QosProfile) -> None:
    assert ours == theirs.encode()
    assert QosProfile.decode(ours) == theirs


def test_keys_and_tokens_by_hand() -> None:
    assert graph.dds_type_name(JOINT_STATE) == "sensor_msgs::msg::dds_::JointState_"
    assert graph.ros_type_name("sensor_msgs::msg::dds_::JointState_") == JOINT_STATE
    assert graph.qualified("/", "deltadash", "joint_states") == "/joint_states"
    assert graph.qualified("/lab", "deltadash", "joint_states") == "/lab/joint_states"
    assert graph.qualified("/lab", "deltadash", "~/state") == "/lab/deltadash/state"
    assert graph.qualified("/lab", "deltadash", "/tf") == "/tf"
    for bad in ("", "a b", "a//b", "tf/", "1tf"):
        with pytest.raises(ValueError, match="topic"):
            graph.qualified("/", "n", bad)
    assert (
        graph.topic_key("rmw_zenoh", 3, "/delta/tip_pose", POSE, "RIHS01_ab")
        == "3/delta/tip_pose/geometry_msgs::msg::dds_::PoseStamped_/RIHS01_ab"
    )
    assert graph.topic_key("bridge", 3, "/delta/tip_pose", POSE, "x") == "delta/tip_pose"
    node = graph.GraphNode(3, "abc123", 0, "/lab", "deltadash")
    assert node.token() == "@ros2_lv/3/abc123/0/0/NN/%/%lab/deltadash"
    assert (
        node.endpoint_token(
            2, "publisher", "/joint_states", JOINT_STATE, "RIHS01_ab", "::,10:,:,:,,"
        )
        == "@ros2_lv/3/abc123/0/2/MP/%/%lab/deltadash/%joint_states/"
        "sensor_msgs::msg::dds_::JointState_/RIHS01_ab/::,10:,:,:,,"
    )
    assert graph.GraphNode(0, "z", 0, "/", "n").token() == "@ros2_lv/0/z/0/0/NN/%/%/n"


def test_diagnostics_warn_on_the_loops_light_not_on_one_overrun(messages: Messages) -> None:
    from app.control.timing import TimingStats

    one = Snapshot(mode="idle", loop_window=TimingStats(200, 200, 5, 0.01, 0.02, 0.5, 1, 2000, 5.2))
    (status,) = _decode(messages, messages.diagnostics(one, 1.0), DIAGNOSTICS).status
    assert status.level == 0  # one overrun in 2000 ticks: the light is green
    bad = Snapshot(mode="jog", loop_window=TimingStats(200, 150, 5, 0.01, 8, 30, 400, 2000, 40))
    (status,) = _decode(messages, messages.diagnostics(bad, 1.0), DIAGNOSTICS).status
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == 1 and status.message.startswith("the loop (red): 400 of 2000")
    assert values["loop_health"] == "red"

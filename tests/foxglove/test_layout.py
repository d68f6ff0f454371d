"""The shipped Foxglove layout (docs/foxglove/deltadash.json): the generator's output for
the default config, and every topic, field and frame it names is one the live server
publishes."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from app.config import load_settings
from app.control.state import Snapshot
from app.foxglove import layout, messages

SHIPPED = Path(__file__).resolve().parents[2] / "docs" / "foxglove" / "deltadash.json"


def _panels(tree) -> list[str]:
    if isinstance(tree, str):
        return [tree]
    return _panels(tree["first"]) + _panels(tree["second"])


def test_the_shipped_layout_is_the_generated_one():
    settings = load_settings()
    assert SHIPPED.read_text() == layout.layout_json(settings), (
        "regenerate it: python -m app.foxglove.layout > docs/foxglove/deltadash.json"
    )


def test_every_panel_is_placed_and_reads_what_is_published():
    settings = load_settings()
    shipped = json.loads(SHIPPED.read_text())
    configs = shipped["configById"]
    assert sorted(_panels(shipped["layout"])) == sorted(configs)  # each panel shown once
    kinds = {panel_id.split("!")[0] for panel_id in configs}
    assert {"3D", "Plot", "RosOut", "RawMessages"} <= kinds

    snap = Snapshot(
        platform_measured_m=np.zeros(3),
        point_measured_m=np.zeros(3),
        point_commanded_m=np.zeros(3),
        goal_m=np.zeros(3),
        torque=True,
    )
    bodies = {messages.TRACKING: messages.tracking(snap), messages.LOOP: messages.loop_health(snap)}
    joints = len(settings.ros2.joint_names)
    for config in configs.values():
        for series in config.get("paths", []):
            topic, _, path = series["value"].partition(".")
            assert topic in messages.TOPICS, series
            if topic in bodies:  # a JSON field the message has, and its schema names
                value = bodies[topic]
                for part in path.split("."):
                    value = value[part]
                assert isinstance(value, float | int), series
                schema = {
                    messages.TRACKING: messages.TRACKING_SCHEMA,
                    messages.LOOP: messages.LOOP_SCHEMA,
                }[topic]
                assert path.split(".")[0] in schema["properties"]
            else:
                match = re.fullmatch(r"joints\[(\d)\]\.position", path)
                assert topic == messages.JOINT_STATES and match, series
                assert int(match.group(1)) < joints

    three_d = configs[layout.THREE_D]
    assert three_d["followTf"] == settings.ros2.base_frame
    assert set(three_d["topics"]) == {messages.TF}
    frames = {key.removeprefix("frame:") for key in three_d["transforms"]}
    ros = settings.ros2
    published = {ros.drone_frame, ros.base_frame, ros.platform_frame, ros.tip_frame}
    assert frames == published | {settings.foxglove.goal_frame}
    assert configs[layout.LOG_PANEL]["topicToRender"] == messages.LOG
    assert configs[layout.RUNS_PANEL]["topicPath"] == messages.RUNS

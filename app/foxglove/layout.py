"""The Foxglove layout shipped with deltadash (docs/foxglove/deltadash.json).

The layout is the file the Foxglove app exports and imports (Layouts, "Import from
file..."): ``configById`` (each panel's settings, keyed ``Type!id``), ``layout`` (the
split tree of panel ids), ``globalVariables``, ``userNodes``, ``playbackConfig``. It
opens the live server's channels (messages.py): a 3D panel following the Delta's base
frame (the base, the platform, the tip and the goal as frames), plots of the tracking
error, the joints and the loop's health, the Log panel on the faults and runs, and the
latest run event. The frame names are the config's (``[ros2]``, ``foxglove.goal_frame``);
the shipped file is this module's output for the defaults:

    python -m app.foxglove.layout > docs/foxglove/deltadash.json
    python -m app.foxglove.layout --config robot.toml > my-layout.json   # other names
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from app.config import Settings, load_settings
from app.foxglove import messages

THREE_D = "3D!deltadash"
PLOT_ERROR = "Plot!tracking"
PLOT_JOINTS = "Plot!joints"
PLOT_RATE = "Plot!loop_rate"
PLOT_LATENESS = "Plot!loop_lateness"
LOG_PANEL = "RosOut!log"
RUNS_PANEL = "RawMessages!runs"
COLORS = ("#e6194b", "#3cb44b", "#4363d8", "#f58231")


def _series(path: str, label: str, color: str) -> dict[str, Any]:
    return {
        "value": path,
        "enabled": True,
        "timestampMethod": "receiveTime",
        "label": label,
        "color": color,
    }


def _plot(title: str, series: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "foxglovePanelTitle": title,
        "paths": series,
        "showXAxisLabels": True,
        "showYAxisLabels": True,
        "showLegend": True,
        "legendDisplay": "floating",
        "showPlotValuesInLegend": True,
        "isSynced": True,
        "xAxisVal": "timestamp",
        "followingViewWidth": 30,
        "sidebarDimension": 240,
    }


def _three_d(settings: Settings) -> dict[str, Any]:
    ros = settings.ros2
    frames = (ros.drone_frame, ros.base_frame, ros.platform_frame, ros.tip_frame)
    frames_shown = (*frames, settings.foxglove.goal_frame)
    return {
        "foxglovePanelTitle": "Delta: base, platform, tip, goal",
        "cameraState": {
            "perspective": True,
            "distance": 0.9,
            "phi": 65,
            "thetaOffset": 45,
            "target": [0, 0, 0],
            "targetOffset": [0, 0, -0.15],
            "targetOrientation": [0, 0, 0, 1],
            "fovy": 45,
            "near": 0.005,
            "far": 100,
        },
        "followMode": "follow-pose",
        "followTf": ros.base_frame,
        "scene": {
            "transforms": {"showLabel": True, "labelSize": 0.02, "axisScale": 0.3},
        },
        "transforms": {f"frame:{name}": {"visible": True} for name in frames_shown},
        "topics": {messages.TF: {"visible": True}},
        "layers": {
            "grid": {
                "visible": True,
                "frameLocked": True,
                "label": "Grid (10 cm)",
                "instanceId": "grid",
                "layerId": "foxglove.Grid",
                "frameId": ros.base_frame,
                "size": 1,
                "divisions": 10,
                "lineWidth": 1,
                "color": "#248eff",
                "position": [0, 0, -0.35],
                "rotation": [0, 0, 0],
            }
        },
        "publish": {"type": "point", "poseTopic": "", "pointTopic": "", "poseEstimateTopic": ""},
        "imageMode": {},
    }


def layout(settings: Settings) -> dict[str, Any]:
    """The layout for ``settings``' frame and joint names."""
    tracking, loop = messages.TRACKING, messages.LOOP
    error = [_series(f"{tracking}.error_norm_mm", "|error| [mm]", COLORS[3])]
    error += [
        _series(f"{tracking}.error_mm.{axis}", f"{axis} [mm]", color)
        for axis, color in zip("xyz", COLORS, strict=False)
    ]
    joints = [
        _series(f"{messages.JOINT_STATES}.joints[{i}].position", f"{name} [rad]", COLORS[i])
        for i, name in enumerate(settings.ros2.joint_names)
    ]
    config_by_id: dict[str, Any] = {
        THREE_D: _three_d(settings),
        PLOT_ERROR: _plot("Tracking error (commanded - measured tip)", error),
        PLOT_JOINTS: _plot("Joint positions (measured)", joints),
        PLOT_RATE: _plot(
            "Loop rate [Hz]",
            [
                _series(f"{loop}.rate_hz", "rate [Hz] (last 10 s)", COLORS[2]),
                _series(f"{loop}.target_hz", "target [Hz]", COLORS[1]),
            ],
        ),
        PLOT_LATENESS: _plot(
            "Loop lateness [ms] and overruns",
            [
                _series(f"{loop}.lateness_p99_ms", "lateness p99 [ms] (last 10 s)", COLORS[0]),
                _series(f"{loop}.lateness_ms", "lateness [ms] (tick)", COLORS[2]),
                _series(f"{loop}.overruns_10s", "overruns (last 10 s)", COLORS[3]),
            ],
        ),
        LOG_PANEL: {
            "foxglovePanelTitle": "Faults, e-stop and runs",
            "topicToRender": messages.LOG,
            "searchTerms": [],
            "minLogLevel": 1,
        },
        RUNS_PANEL: {
            "foxglovePanelTitle": "Latest run event",
            "topicPath": messages.RUNS,
            "diffEnabled": False,
            "diffMethod": "custom",
            "diffTopicPath": "",
            "showFullMessageForDiff": False,
            "expansion": "all",
        },
    }
    tree = {
        "direction": "row",
        "splitPercentage": 45,
        "first": THREE_D,
        "second": {
            "direction": "column",
            "splitPercentage": 50,
            "first": {"direction": "column", "first": PLOT_ERROR, "second": PLOT_JOINTS},
            "second": {
                "direction": "column",
                "first": {"direction": "row", "first": PLOT_RATE, "second": PLOT_LATENESS},
                "second": {"direction": "row", "first": LOG_PANEL, "second": RUNS_PANEL},
            },
        },
    }
    return {
        "configById": config_by_id,
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": tree,
    }


def layout_json(settings: Settings) -> str:
    """The layout as the file holds it (2-space indent, a final newline)."""
    return json.dumps(layout(settings), indent=2) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m app.foxglove.layout", description="print deltadash's Foxglove layout"
    )
    parser.add_argument("--config", help="a deltadash config file (its frame and joint names)")
    args = parser.parse_args(argv)
    settings = load_settings(args.config)
    sys.stdout.write(layout_json(settings))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

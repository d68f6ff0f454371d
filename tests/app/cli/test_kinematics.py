"""``deltadash ik`` and ``fk``: one set of units, refusals, and ik's output pasted into fk."""

import json
import math
import re

import pytest

from app.cli import main


def _ik_joints(out: str) -> list[str]:
    """The words after "joints" in ik's line, as a person would select and paste them."""
    return out.split("joints", 1)[1].split()


@pytest.mark.parametrize(
    "point_mm", [(0.0, 0.0, -240.0), (35.5, -20.25, -210.0), (-80.0, 60.0, -280.0)]
)
@pytest.mark.parametrize("si", [False, True])
def test_ik_output_pasted_into_fk_gives_back_the_point(capsys, point_mm, si):
    flags = ["--si"] if si else []
    given = [v / 1e3 for v in point_mm] if si else list(point_mm)
    assert main(["ik", *map(str, given), *flags]) == 0
    pasted = _ik_joints(capsys.readouterr().out)
    assert pasted[1].rstrip(",") == ("rad" if si else "deg")  # every number has its unit
    assert main(["fk", *pasted, *flags]) == 0
    out = capsys.readouterr().out
    unit = "m" if si else "mm"
    found = [float(v) for v in re.findall(rf"(-?\d+\.\d+) {unit}\b", out.split("platform")[1])]
    scale = 1e3 if si else 1.0
    assert max(abs(a * scale - b) for a, b in zip(found, point_mm, strict=True)) < 0.01


def test_si_output_pasted_into_a_default_fk_still_means_radians(capsys):
    assert main(["ik", "0", "0", "-0.24", "--si"]) == 0
    pasted = _ik_joints(capsys.readouterr().out)
    assert main(["fk", *pasted, "--json"]) == 0  # default degrees, but each value says rad
    point = json.loads(capsys.readouterr().out)["point_m"]
    assert point == pytest.approx([0, 0, -0.24], abs=1e-5)


def test_ik_json_round_trips_through_fk(capsys):
    assert main(["ik", "0", "0", "-240", "--json"]) == 0
    ik = json.loads(capsys.readouterr().out)
    assert ik["ok"] is True and ik["point_m"] == pytest.approx([0, 0, -0.24])
    assert main(["fk", *map(str, ik["joints_rad"]), "--si", "--json"]) == 0
    fk = json.loads(capsys.readouterr().out)
    assert max(abs(a - b) for a, b in zip(fk["point_m"], [0, 0, -0.24], strict=True)) < 1e-12


def test_fk_refuses_joints_outside_the_configured_limits(capsys):
    # the report of issue 17: 30 "degrees" read as radians gave a point, silently
    assert main(["fk", "30", "30", "30", "--si"]) == 2
    err = capsys.readouterr().err
    assert "joint 1 = 1718.873 deg" in err and "max_angle_rad = 1.65" in err


def test_fk_limits_come_from_the_config(capsys, tmp_path):
    config = tmp_path / "robot.toml"
    joints = "".join(
        f"[[hardware.joints]]\nservo_id = {i}\nmax_angle_rad = 0.4\n" for i in (1, 2, 3)
    )
    config.write_text(joints)
    assert main(["fk", "20", "20", "20"]) == 0
    capsys.readouterr()
    assert main(["fk", "20", "20", "30", "--config", str(config)]) == 2
    err = capsys.readouterr().err
    assert "joint 3 = 30.000 deg" in err and "joint 1" not in err
    assert f"limit {math.degrees(0.4):.3f} deg" in err


def test_unreachable_point_names_the_nearest_one_the_gate_accepts(capsys):
    assert main(["ik", "400", "0", "-200"]) == 1
    out = capsys.readouterr().out
    assert "outside the workspace" in out and "nearest point the gate accepts" in out
    nearest = [float(v) for v in re.findall(r"(-?\d+\.\d+) mm", out.split("nearest")[1])]
    assert main(["ik", *map(str, nearest)]) == 0  # printed to 0.001 mm: IK and joint limits
    assert "joints" in capsys.readouterr().out


def test_the_nearest_point_respects_the_joint_limits_as_the_page_does(capsys):
    """Issue 32 point 6: for (250, 0, -240) mm the page offered (211.2, 0, -233.3) and ik
    (236.973, 0, -233.567), the workspace's nearest point, which needs joint 2 and 3 past
    their 94.5 deg limit. Now ik gives the page's point, and the gate takes it."""
    import numpy as np

    from app.config import Settings
    from app.control.commands import CommandContext

    assert main(["ik", "250", "0", "-240", "--json"]) == 1
    nearest = json.loads(capsys.readouterr().out)["nearest_m"]
    assert nearest == pytest.approx([0.2112, 0.0, -0.2333], abs=1e-4)
    gate = CommandContext.from_settings(Settings()).gate
    home = gate.robot.ik([0.0, 0.0, -0.24]).joints
    gate.solve(gate.check_point(np.array(nearest)), home)  # raises if refused
    assert main(["ik", *(f"{v * 1e3:.3f}" for v in nearest)]) == 0  # as printed


def test_a_point_the_gate_refuses_within_the_limits_is_refused_with_its_reason(capsys):
    """A point IK solves within the joint limits but within the gate's 2 mm margin of the
    workspace's boundary: refused as a goal (exit 1), with the reason and the nearest point."""
    import numpy as np

    from app.cli.kinematics import DEFAULT_JOINT_LIMITS_RAD
    from kinematics import THESIS_DELTA

    rng = np.random.default_rng(7)
    points = rng.uniform([-0.3, -0.3, -0.45], [0.3, 0.3, -0.08], (20000, 3))
    band = THESIS_DELTA.reachable(points, margin=0.0) & ~THESIS_DELTA.reachable(
        points, margin=0.002
    )
    solution = THESIS_DELTA.ik(points[band])
    low, high = DEFAULT_JOINT_LIMITS_RAD
    within = solution.ok & ((solution.joints >= low) & (solution.joints <= high)).all(-1)
    within &= np.asarray(THESIS_DELTA.dexterity(solution.joints)) >= 0.05
    assert within.any()  # the band within the joint limits is sampled
    point = points[band][within][0]
    assert main(["ik", *map(repr, point.tolist()), "--si"]) == 1
    out = capsys.readouterr().out
    assert "refused as a goal" in out and "limits.workspace_margin_m" in out, out
    assert "nearest point the gate accepts" in out


def test_a_point_beyond_a_joint_limit_gets_the_nearest_point_too(capsys):
    assert main(["ik", "50", "0", "-90", "--json"]) == 1
    payload = json.loads(capsys.readouterr().out)
    assert payload["problems"] and len(payload["nearest_m"]) == 3
    assert main(["ik", *map(str, payload["nearest_m"]), "--si", "--json"]) == 0


def test_ik_says_which_joint_limit_a_reachable_point_needs_to_break(capsys):
    # (50, 0, -90) mm is inside the geometric workspace but needs theta_1 = -74 deg
    assert main(["ik", "50", "0", "-90"]) == 1
    out = capsys.readouterr().out
    assert "joint 1 = -74.09" in out and "min_angle_rad = -0.6" in out


@pytest.mark.parametrize(
    "argv, words",
    [
        (["ik", "0", "0", "-240", "deg"], "expected mm or m"),
        (["fk", "30", "30", "30", "mm"], "expected deg or rad"),
        (["ik", "0", "-240"], "expected 3 numbers, got 2"),
        (["fk", "30", "x", "30"], "'x'"),
        (["ik", "12,5", "-240"], "expected 3 numbers, got 2"),  # 12.5, never 12 and 5
        (["ik", "1,2,3"], "'1,2,3' is not one number"),  # never three numbers
        (["ik", "0", "1,234.5", "-240"], "'1,234.5' is not one number"),
        (["fk", "30", "30", "mm30"], "'mm30' is not a number"),
        (["ik", "0", "mm", "mm", "-240"], "'mm' follows no number"),
    ],
)
def test_bad_input_is_refused_with_its_reason(capsys, argv, words):
    assert main(argv) == 2
    assert words in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv",
    [
        ["ik", "10,5", "0", "-240", "--json"],
        ["ik", "10.5", "0", "-240", "--json"],
        ["ik", "(10,5,", "0,", "-240)", "--json"],  # a pasted tuple with a decimal comma
        ["ik", "10,5mm", "0", "-240,0", "mm", "--json"],
        ["ik", "0,0105", "0", "-0,24", "--si", "--json"],
    ],
)
def test_a_decimal_comma_is_a_decimal_point_as_on_the_page(capsys, argv):
    # issue 32 item 7: `deltadash ik 10,5 0 -240` was refused while the page took it
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["point_m"] == pytest.approx([0.0105, 0, -0.24])


def test_a_negative_decimal_comma_is_a_number_not_an_option(capsys):
    assert main(["ik", "-10,5", "0", "-240", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["point_m"] == pytest.approx([-0.0105, 0, -0.24])
    assert main(["fk", "-2,5", "10", "20,25", "--json"]) == 0
    joints = json.loads(capsys.readouterr().out)["joints_rad"]
    assert joints == pytest.approx([math.radians(v) for v in (-2.5, 10, 20.25)])


def test_the_fast_path_uses_the_configs_defaults():
    from app.cli.kinematics import DEFAULT_GATE_LIMITS, DEFAULT_JOINT_LIMITS_RAD
    from app.config import Settings
    from kinematics import THESIS_DELTA

    settings = Settings()
    for joint in settings.hardware.joints:
        assert (joint.min_angle_rad, joint.max_angle_rad) == DEFAULT_JOINT_LIMITS_RAD
    gate = settings.limits
    assert (gate.workspace_margin_m, gate.z_max_m, gate.min_dexterity) == DEFAULT_GATE_LIMITS
    robot = settings.robot.build()
    assert type(robot) is type(THESIS_DELTA)
    for name in ("L", "l", "R", "r"):
        assert getattr(robot, name) == getattr(THESIS_DELTA, name)


def test_environment_settings_are_honoured(capsys, monkeypatch):
    monkeypatch.setenv(
        "DELTADASH_HARDWARE__JOINTS",
        '[{"servo_id": 1, "max_angle_rad": 0.3}, {"servo_id": 2}, {"servo_id": 3}]',
    )
    assert main(["fk", "20", "20", "20"]) == 2
    assert "joint 1 = 20.000 deg" in capsys.readouterr().err


def test_a_config_with_robot_legs_gives_the_per_leg_ik_and_fk(tmp_path, capsys):
    """ik and fk with a config a geometry calibration wrote ([robot.legs]) use its robot."""
    import json

    import numpy as np

    from kinematics import THESIS_DELTA, PerLegRotaryDelta

    legs = PerLegRotaryDelta.from_symmetric(THESIS_DELTA, l=(0.2440, 0.2425, 0.2430))
    config = tmp_path / "robot.toml"
    config.write_text("[robot.legs]\nlower_link_m = [0.2440, 0.2425, 0.2430]\n")
    assert main(["ik", "0.02", "0", "-0.24", "--si", "--json", "--config", str(config)]) == 0
    joints = json.loads(capsys.readouterr().out)["joints_rad"]
    np.testing.assert_allclose(joints, legs.ik([0.02, 0.0, -0.24]).joints, atol=1e-12)
    assert not np.allclose(joints, THESIS_DELTA.ik([0.02, 0.0, -0.24]).joints, atol=1e-4)
    assert main(["fk", *map(str, joints), "--si", "--json", "--config", str(config)]) == 0
    point = json.loads(capsys.readouterr().out)["point_m"]
    np.testing.assert_allclose(point, [0.02, 0.0, -0.24], atol=1e-12)

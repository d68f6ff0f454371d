"""Config loading: defaults, TOML, environment, overrides and clear errors."""

from __future__ import annotations

import pytest

from app.cli import main
from app.config import ConfigError, load_settings
from kinematics import THESIS_DELTA


def test_defaults_are_the_thesis_robot_on_localhost():
    settings = load_settings()
    assert settings.robot.build() == THESIS_DELTA
    assert settings.server.host == "127.0.0.1" and settings.loop.rate_hz == 200.0


def test_toml_then_env_then_overrides(tmp_path, monkeypatch):
    path = tmp_path / "robot.toml"
    path.write_text('[hardware]\nport = "/dev/ttyACM0"\nbaud = 57600\n[loop]\nrate_hz = 100\n')
    settings = load_settings(path)
    assert settings.hardware.port == "/dev/ttyACM0" and settings.loop.rate_hz == 100
    monkeypatch.setenv("DELTADASH_LOOP__RATE_HZ", "250")
    assert load_settings(path).loop.rate_hz == 250
    merged = load_settings(path, hardware={"baud": 4_000_000})
    assert merged.hardware.baud == 4_000_000 and merged.hardware.port == "/dev/ttyACM0"


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("[robot]\nl = 0.1\n", "robot"),
        ("[hardware]\nbaud = 5\n", "hardware.baud"),
        ("[loop]\nrate_hz = -1\n", "loop.rate_hz"),
        ("[loop]\nrate = 100\n", "loop.rate"),
        ('[hardware]\nbackend = "usb"\n', "hardware.backend"),
        ("[[hardware.joints]]\nservo_id = 1\n", "hardware.joints"),
        ("[server\n", "cannot read"),
    ],
)
def test_bad_config_names_the_field(tmp_path, text, field):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        load_settings(path)


def test_serve_refuses_a_bad_config_at_start(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text("[loop]\nrate_hz = 0\n")
    assert main(["serve", "--config", str(path)]) == 2
    assert "loop.rate_hz" in capsys.readouterr().err


JOINTS = "".join(
    f"[[hardware.joints]]\nservo_id = {i}\nzero_offset_ticks = {2000 + i}\n" for i in (4, 5, 6)
)


def test_nested_sections_come_from_the_toml_file(tmp_path):
    path = tmp_path / "robot.toml"
    path.write_text('[hardware]\nbackend = "emulated"\n' + JOINTS)
    hardware = load_settings(path).hardware
    assert hardware.backend == "emulated"
    assert [(j.servo_id, j.zero_offset_ticks) for j in hardware.joints] == [
        (4, 2004),
        (5, 2005),
        (6, 2006),
    ]


@pytest.mark.parametrize(
    ("text", "field"),
    [
        (JOINTS + "zero_ticks = 0\n", "hardware.joints.2.zero_ticks"),
        ("[server]\nport = 8001\n", "server.port"),
        ("[serve]\nhttp_port = 8001\n", "serve"),
    ],
)
def test_a_wrong_key_names_its_dotted_path(tmp_path, text, field):
    path = tmp_path / "typo.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=field.replace(".", r"\.") + ": Extra inputs"):
        load_settings(path)


def test_a_missing_config_file_is_an_error_not_the_defaults(tmp_path):
    with pytest.raises(ConfigError, match="cannot read config"):
        load_settings(tmp_path / "absent.toml")


def test_robot_legs_give_a_per_leg_robot_and_without_them_nothing_changes(tmp_path, monkeypatch):
    """[robot.legs] (what a geometry calibration writes) is the controller's model; a leg
    value left out is [robot]'s; L, l, R, r stay the drawing (``symmetric``)."""
    from kinematics import PerLegRotaryDelta, RotaryDelta

    assert type(load_settings().robot.build()) is RotaryDelta
    path = tmp_path / "robot.toml"
    path.write_text("[robot]\nl = 0.244\n[robot.legs]\nupper_link_m = [0.156, 0.1555, 0.1558]\n")
    robot = load_settings(path).robot
    assert robot.build() == PerLegRotaryDelta.from_symmetric(
        RotaryDelta(0.1558, 0.244, 0.0844, 0.038), L=(0.156, 0.1555, 0.1558)
    )
    assert robot.symmetric() == RotaryDelta(0.1558, 0.244, 0.0844, 0.038)
    monkeypatch.setenv("DELTADASH_ROBOT__LEGS__LOWER_LINK_M", "[0.2441, 0.2432, 0.2425]")
    assert load_settings().robot.build().l == (0.2441, 0.2432, 0.2425)


@pytest.mark.parametrize(
    ("legs", "field"),
    [
        ({"lower_link_m": [0.1, 0.243, 0.243]}, "robot.legs.lower_link_m: l[0] = 0.1 m"),
        ({"platform_radius_m": [0.03, 0.09, 0.03]}, "robot.legs.platform_radius_m: r[1]"),
        ({"base_radius_m": [0.08, 0.08]}, "robot.legs.base_radius_m"),
        ({"upper_link": [0.15, 0.15, 0.15]}, "robot.legs.upper_link"),
    ],
)
def test_bad_robot_legs_name_the_field(legs, field):
    with pytest.raises(ConfigError, match=field.replace("[", r"\[")):
        load_settings(robot={"legs": legs})


def test_robot_legs_are_for_rotary_deltas():
    with pytest.raises(ConfigError, match="robot.legs: per-leg geometry is for rotary"):
        load_settings(robot={"type": "linear", "legs": {"lower_link_m": [0.3, 0.3, 0.3]}})

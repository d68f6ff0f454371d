"""``deltadash home`` against emulated servos: offsets computed, saved and loaded back."""

from __future__ import annotations

import math

from app.cli import main
from app.config import load_settings
from hardware.emulator import ServoEmulator
from tests.support.servo_emulator import fast


def test_home_saves_offsets_that_make_the_pose_read_as_its_angles(tmp_path, capsys):
    config = tmp_path / "robot.toml"
    config.write_text("[server]\nhttp_port = 8123\n")  # other sections must survive
    with fast(ServoEmulator((1, 2, 3))) as emulator:
        emulator.place({1: 2100, 2: 1990, 3: 2300})  # the links resting on a jig
        code = main(
            [
                "home",
                "--config",
                str(config),
                "--port",
                emulator.port,
                "--angles-deg",
                "0",
                "0",
                "10",
                "--yes",
            ]
        )
    assert code == 0 and "saved" in capsys.readouterr().out
    settings = load_settings(config)
    assert settings.server.http_port == 8123
    offsets = [j.zero_offset_ticks for j in settings.hardware.joints]
    ticks_per_rad = 4096 / (2 * math.pi)
    assert offsets[:2] == [2100, 1990]
    assert offsets[2] == 2300 - round(math.radians(10) * ticks_per_rad)


def test_home_reports_a_missing_bus(tmp_path, capsys):
    code = main(
        ["home", "--config", str(tmp_path / "x.toml"), "--port", "/dev/nonexistent", "--yes"]
    )
    assert code != 0 and "error" in capsys.readouterr().err


def test_home_refuses_a_range_across_the_seam_and_saves_nothing(tmp_path, capsys):
    # Servo 2 rests at raw 4000 with direction +1 and limits -0.6 .. 1.4 rad: its range
    # would be 4000 - 391 .. 4000 + 913 = 3609 .. 4913 ticks, past 4095.
    config = tmp_path / "robot.toml"
    joints = "".join(
        f"[[hardware.joints]]\nservo_id = {i}\nmin_angle_rad = -0.6\nmax_angle_rad = 1.4\n\n"
        for i in (1, 2, 3)
    )
    config.write_text(joints)
    with fast(ServoEmulator((1, 2, 3))) as emulator:
        emulator.place({1: 2048, 2: 4000, 3: 2048})
        code = main(["home", "--config", str(config), "--port", emulator.port, "--yes"])
    err = capsys.readouterr().err
    assert code == 1 and "servo 2 (joint 2)" in err and "3609 .. 4913 ticks" in err
    assert "391 .. 3182" in err  # where theta = 0 must read after turning the link
    assert config.read_text() == joints


def test_home_calibrates_the_legs_and_keeps_the_wrist_s_section(tmp_path, capsys):
    config = tmp_path / "robot.toml"
    config.write_text("[wrist]\nenabled = true\nservo_id = 4\nzero_offset_ticks = 1000\n")
    with fast(ServoEmulator((1, 2, 3, 4))) as emulator:
        emulator.place({1: 2100, 2: 1990, 3: 2300, 4: 3000})
        code = main(["home", "--config", str(config), "--port", emulator.port, "--yes"])
    assert code == 0, capsys.readouterr().err
    settings = load_settings(config)
    assert [j.zero_offset_ticks for j in settings.hardware.joints] == [2100, 1990, 2300]
    assert settings.wrist.enabled and settings.wrist.zero_offset_ticks == 1000  # untouched

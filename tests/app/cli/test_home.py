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

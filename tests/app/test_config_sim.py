"""``[hardware.sim]``: the twin built wrong on purpose, from TOML and the environment."""

from __future__ import annotations

import numpy as np
import pytest

from app.config import ConfigError, load_settings
from app.server.backends import _twin
from hardware.encoder import RAD_PER_TICK
from kinematics import THESIS_DELTA, PerLegRotaryDelta

WRONG = """
[hardware]
sim_process = false
[hardware.sim]
true_joint_offsets_rad = [0.05, -0.03, 0.02]
true_lower_link_m = [0.2440, 0.2425, 0.2430]
true_base_radius_m = [0.0844, 0.0850, 0.0844]
measurement_frame_position_m = [0.1, 0.0, -0.5]
measurement_frame_rpy_rad = [0.0, 0.0, 1.5]
measurement_noise_m = 0.0003
"""


def test_the_defaults_are_the_exact_twin():
    settings = load_settings(hardware={"sim_process": False})
    assert settings.hardware.sim.true_robot(THESIS_DELTA) is None
    config = _twin(settings).config
    assert config.twin.true_robot is None and config.noise_std_m == 0.0
    assert config.measurement_frame_position_m == (0.0, 0.0, 0.0)
    assert config.measurement_frame_rpy_rad == (0.0, 0.0, 0.0)


def test_the_twin_is_built_from_the_section(tmp_path):
    path = tmp_path / "wrong.toml"
    path.write_text(WRONG)
    settings = load_settings(path)
    expected = PerLegRotaryDelta.from_symmetric(
        THESIS_DELTA,
        joint_offsets_rad=(0.05, -0.03, 0.02),
        l=(0.2440, 0.2425, 0.2430),
        R=(0.0844, 0.0850, 0.0844),
    )
    bus = _twin(settings)
    assert bus.config.twin.true_robot == expected
    assert bus.config.twin.robot == THESIS_DELTA  # the controller's model is unchanged
    assert bus.config.noise_std_m == 0.0003
    assert bus.config.measurement_frame_rpy_rad == (0.0, 0.0, 1.5)
    # what the calibration makes of the shafts is theta - o
    twin = bus.twin
    reported = twin.joints_of_shafts(twin.shaft_rad) - np.array(expected.joint_offsets_rad)
    np.testing.assert_allclose(
        [c.to_rad(s / RAD_PER_TICK) for c, s in zip(bus.joints, twin.shaft_rad, strict=True)],
        reported,
        atol=1e-12,
    )


def test_the_environment_sets_a_per_leg_value(monkeypatch):
    monkeypatch.setenv("DELTADASH_HARDWARE__SIM__TRUE_UPPER_LINK_M", "[0.156, 0.1558, 0.155]")
    robot = load_settings().hardware.sim.true_robot(THESIS_DELTA)
    assert robot is not None and robot.L == (0.156, 0.1558, 0.155)


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("true_lower_link_m = [0.1, 0.243, 0.243]", "hardware.sim.true_lower_link_m"),
        ("true_platform_radius_m = [0.038, 0.09, 0.038]", "hardware.sim.true_platform_radius_m"),
        ("true_upper_link_m = [0.15, 0.15]", "hardware.sim.true_upper_link_m"),
        ("true_joint_offsets_rad = [0.0, nan, 0.0]", "hardware.sim.true_joint_offsets_rad"),
        ("measurement_noise_m = -1.0", "hardware.sim.measurement_noise_m"),
        ("measurement_frame_rpy = [0.0, 0.0, 0.0]", "hardware.sim.measurement_frame_rpy"),
    ],
)
def test_a_bad_value_names_its_field(tmp_path, text, field):
    path = tmp_path / "bad.toml"
    path.write_text(f"[hardware.sim]\n{text}\n")
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        load_settings(path)

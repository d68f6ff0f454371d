"""The [tool] section: the tip offset, its checks and its default (no tool)."""

from __future__ import annotations

import numpy as np
import pytest

from app.config import ConfigError, load_settings


def test_no_tool_section_is_a_zero_offset_without_wrist():
    tool = load_settings().tool.build()
    assert tool.offset_m == (0.0, 0.0, 0.0) and not tool.wrist
    np.testing.assert_array_equal(tool.tip([0.01, -0.02, -0.24]), [0.01, -0.02, -0.24])


def test_tool_offset_from_the_toml_file(tmp_path):
    path = tmp_path / "robot.toml"
    path.write_text("[tool]\noffset_m = [0.01, 0.0, -0.05]\n")
    tool = load_settings(path).tool.build()
    np.testing.assert_allclose(tool.tip([0.0, 0.0, -0.2]), [0.01, 0.0, -0.25])


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("offset_m = [0.0, nan, 0.0]", "finite"),
        ("offset_m = [0.0, 0.0, inf]", "finite"),
        ("offset_m = [0.0, 0.0, -50.0]", "millimetres"),
        ("offset_m = [0.0, 0.0]", "offset_m"),
        ('offset_m = "down"', "offset_m"),
        ("length_m = 0.05", "length_m"),
    ],
)
def test_a_bad_tool_names_the_field_and_why(tmp_path, text, reason):
    path = tmp_path / "bad.toml"
    path.write_text(f"[tool]\n{text}\n")
    with pytest.raises(ConfigError, match=r"tool\.") as info:
        load_settings(path)
    assert reason in str(info.value)

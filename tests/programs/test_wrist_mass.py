"""A program's torque check carries the wrist's mass when a wrist is fitted."""

from __future__ import annotations

import pytest

from app.config import load_settings
from app.programs.check import verify_limits
from kinematics.dynamics import THESIS_MASS, WRIST_XM430


def test_the_torque_check_weighs_the_wrist_only_when_it_is_enabled() -> None:
    plain = verify_limits(load_settings(programs={"payload_kg": 0.05})).mass
    wrist = verify_limits(load_settings(programs={"payload_kg": 0.05}, wrist={"enabled": True}))
    assert plain is not None and wrist.mass is not None
    assert plain.platform_kg == pytest.approx(0.025 + 0.05)
    # XM430-W210 case 82 g + 20 g horn and tool
    assert wrist.mass.platform_kg == pytest.approx(0.025 + 0.05 + 0.082 + 0.020)
    assert THESIS_MASS.with_wrist(WRIST_XM430).platform_kg == pytest.approx(0.127)
    assert wrist.mass.upper_inertia_kgm2 == plain.upper_inertia_kgm2

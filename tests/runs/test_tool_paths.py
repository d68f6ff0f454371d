"""Runs move the tool tip: a planned path's check is the platform path's, named by tips."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from app.config import load_settings
from app.control.commands import CommandContext
from app.control.errors import GoalRejected
from app.runs.feasibility import check_path
from app.runs.trajectories import SinusoidParams, sinusoid_points
from kinematics import Tool

PLAIN = CommandContext.from_settings(load_settings()).gate
DOWN = np.array([0.0, 0.0, -0.05])
TOOLED = dataclasses.replace(PLAIN, tool=Tool(offset_m=tuple(DOWN)))
NEAR = PLAIN.robot.ik([0.0, 0.0, -0.24]).joints


def _times(duration_s: float) -> np.ndarray:
    return np.arange(0.0, duration_s, 0.005)


def test_a_tip_sinusoid_is_checked_as_its_platform_path():
    """The thesis sinusoid about a tip 5 cm lower passes with the tool, as the same
    sinusoid about the platform centre passes without."""
    times = _times(2.0)
    tips = sinusoid_points(SinusoidParams(offset_m=(0.0, 0.0, -0.29)), times)
    check_path(TOOLED, times, tips, NEAR)
    check_path(PLAIN, times, tips - DOWN, NEAR)


def test_a_tip_path_whose_platform_leaves_is_refused_naming_the_tip():
    """Rising to z = -0.09: fine for the platform, but the tool would lift the platform 5 cm
    higher, out of its workspace; the refusal names the tip where that first happens."""
    times = _times(1.0)
    tips = np.zeros((len(times), 3))
    tips[:, 2] = np.linspace(-0.24, -0.09, len(times))
    check_path(PLAIN, times, tips, NEAR)
    with pytest.raises(GoalRejected, match="infeasible: outside the workspace") as info:
        check_path(TOOLED, times, tips, NEAR)
    first = next(i for i, tip in enumerate(tips) if not PLAIN.inside(tip - DOWN))
    assert f"t = {times[first]:.3f} s, point [0.0000, 0.0000, {tips[first, 2]:.4f}]" in str(
        info.value
    )

"""Workspace analysis (kinematics/analysis.py): volume, largest regions, sections."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics import THESIS_DELTA
from kinematics.analysis import largest_region, section, workspace_volume
from kinematics.containment import certify_box, certify_cylinder


def test_volume_estimates_agree_within_their_error_bounds():
    coarse = workspace_volume(THESIS_DELTA, cells_per_axis=40)
    fine = workspace_volume(THESIS_DELTA, cells_per_axis=100)
    assert abs(coarse.volume_m3 - fine.volume_m3) <= coarse.boundary_m3 + fine.boundary_m3
    assert 0.02 < fine.volume_m3 < 0.1


@pytest.mark.parametrize("anchor", ["centre", "top"])
def test_largest_box_is_contained_and_maximal(anchor):
    fit = largest_region(THESIS_DELTA, (1.0, 1.0, 0.5), z=-0.22, anchor=anchor)
    lower, upper = np.array(fit.lower), np.array(fit.upper)
    assert certify_box(THESIS_DELTA, lower, upper, tol=1e-5).contains is True  # 0.01 mm
    size = np.array(fit.size_m)
    assert size[2] == pytest.approx(size[0] / 2)
    grow = 1.0 + 2e-3 / size.max()  # 1 mm more on each side
    centre = 0.5 * (lower + upper)
    if anchor == "top":
        centre[2] = upper[2] - size[2] * grow / 2
    assert (
        certify_box(THESIS_DELTA, centre - size * grow / 2, centre + size * grow / 2).contains
        is False
    )


def test_largest_cylinder_is_contained_and_maximal():
    fit = largest_region(THESIS_DELTA, (2.0, 2.0, 1.0), z=-0.3, shape="cylinder")
    radius, low, high = fit.size_m[0] / 2, fit.lower[2], fit.upper[2]
    assert certify_cylinder(THESIS_DELTA, radius, low, high, tol=1e-5).contains is True
    k = 1.0 + 3 * fit.resolution_m / fit.size_m[0]
    middle, half = 0.5 * (low + high), 0.5 * (high - low) * k
    assert (
        certify_cylinder(THESIS_DELTA, radius * k, middle - half, middle + half).contains is False
    )


def test_section_maps_are_nan_exactly_outside():
    cut = section(THESIS_DELTA, "xy", -0.25, n=41)
    assert cut.dexterity.shape == (41, 41)
    assert np.isnan(cut.dexterity[~cut.reachable]).all()
    assert (cut.dexterity[cut.reachable] > 0).all() and (cut.dexterity[cut.reachable] <= 1).all()
    np.testing.assert_array_equal(cut.reachable, THESIS_DELTA.reachable(cut.points))

"""The scene draws what the kinematics says: links, tori (thesis Table 4.1), the volume."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from app.scene.geometry import robot_lines, torus_mesh, torus_spec
from app.scene.volume import reachable_volume, volume_field
from kinematics import THESIS_DELTA, LinearDelta, RotaryDelta
from tests.support.strategies import joint_range, linear_deltas, rotary_deltas

ALPHAS = (0.0, 2 * math.pi / 3, 4 * math.pi / 3)


def _reachable_joints(robot, fractions) -> np.ndarray:
    """Joints with an FK solution, picked by ``fractions`` in [0, 1]^3 of the joint range
    (any design, even one whose workspace is too small to mesh at a coarse step)."""
    low, high = joint_range(robot)
    joints = low + np.asarray(fractions) * (high - low)
    assume(bool(robot.fk(joints).ok))
    return joints


@settings(max_examples=25)
@given(st.one_of(rotary_deltas(), linear_deltas()), st.tuples(*[st.floats(0, 1)] * 3))
def test_link_endpoints_are_the_kinematics_points(robot, fractions):
    joints = _reachable_joints(robot, fractions)
    hips, knees, ankles = robot.leg_points(joints)
    lines = robot_lines(robot, joints)
    np.testing.assert_allclose(lines.upper[:, 0], hips, atol=1e-12)
    np.testing.assert_allclose(lines.upper[:, 1], knees, atol=1e-12)
    # The two rods of a leg straddle the knee-ankle line and are parallel, length l.
    np.testing.assert_allclose(lines.rods[:, :, 0].mean(axis=1), knees, atol=1e-12)
    np.testing.assert_allclose(lines.rods[:, :, 1].mean(axis=1), ankles, atol=1e-12)
    rods = lines.rods[:, :, 1] - lines.rods[:, :, 0]
    np.testing.assert_allclose(np.linalg.norm(rods, axis=-1), robot.l, rtol=1e-9)
    np.testing.assert_allclose(
        lines.rods[:, :, 1].mean(axis=(0, 1)), robot.fk(joints).points, atol=1e-12
    )


@given(rotary_deltas())
def test_tori_follow_thesis_table_4_1(robot):
    for leg, alpha in enumerate(ALPHAS):
        spec = torus_spec(robot, leg)
        Rbar = robot.R - robot.r
        np.testing.assert_allclose(
            spec.centre, [Rbar * math.cos(alpha), Rbar * math.sin(alpha), 0.0], atol=1e-15
        )
        np.testing.assert_allclose(spec.axis, [-math.sin(alpha), math.cos(alpha), 0.0], atol=1e-15)
        assert spec.major_radius == robot.L  # external radius
        assert spec.tube_radius == robot.l  # internal radius


def _local(points: np.ndarray, alpha: float) -> np.ndarray:
    """Base frame -> leg i's local frame (rotation by -alpha about z)."""
    c, s = math.cos(alpha), math.sin(alpha)
    x, y = c * points[:, 0] + s * points[:, 1], -s * points[:, 0] + c * points[:, 1]
    return np.stack([x, y, points[:, 2]], -1)


@settings(max_examples=20)
@given(rotary_deltas())
def test_torus_mesh_is_the_lower_half_of_eq_4_4(robot):
    L, l, Rbar = robot.L, robot.l, robot.R - robot.r
    for leg, alpha in enumerate(ALPHAS):
        vertices, faces = torus_mesh(robot, leg)
        x, y, z = _local(vertices, alpha).T
        # Eq. 4.4 as corrected in the seeds' README:
        # [(x-Rbar)^2 + y^2 + z^2 + L^2 - l^2]^2 = 4 L^2 [(x-Rbar)^2 + z^2]
        rho2 = (x - Rbar) ** 2 + z**2
        torus = (rho2 + y**2 + L**2 - l**2) ** 2 - 4 * L**2 * rho2
        assert np.abs(torus).max() <= 1e-9 * (L + l) ** 4
        # The same surface is the kinematics' own leg boundary h_i = 0 (eq. 4.2).
        scale = (2 * L * (L + l + Rbar)) ** 2
        assert np.abs(robot.h(vertices)[:, leg]).max() <= 1e-9 * scale
        assert vertices[:, 2].max() <= 1e-12  # lower half only
        assert vertices[:, 2].min() == pytest.approx(-(L + l), rel=1e-3)  # down to the bottom
        assert faces.min() >= 0 and faces.max() < len(vertices)


@settings(max_examples=10)
@given(linear_deltas())
def test_linear_legs_draw_cylinders_about_the_rails(robot):
    for leg in range(3):
        vertices, _ = torus_mesh(robot, leg)
        distance = robot._leg_signed_distance(leg, *vertices.T)
        np.testing.assert_allclose(distance, 0.0, atol=1e-9)
        assert vertices[:, 2].max() <= 1e-9


VOLUME_CASES = [
    (THESIS_DELTA, 0.002, -0.06),
    (RotaryDelta(L=0.1, l=0.25, R=0.1, r=0.03), 0.0, -0.02),
    (LinearDelta(l=0.25, R=0.15, r=0.04), 0.002, -0.06),
    (LinearDelta(l=0.3, R=0.15, r=0.04, incline=math.radians(35)), 0.0, -0.05),
]


@pytest.mark.slow
@pytest.mark.parametrize(("robot", "margin", "z_max"), VOLUME_CASES)
def test_volume_mesh_lies_on_the_gates_boundary(robot, margin, z_max):
    mesh = reachable_volume(robot, margin, z_max)
    field = volume_field(robot, mesh.vertices, margin, z_max)
    assert np.abs(field).max() <= 1e-6  # on the boundary to a micrometre
    # Every vertex passes the reachability test with the margin, to within a micrometre.
    assert (robot.signed_distance(mesh.vertices) <= -margin + 1e-6).all()
    if margin > 1e-6:
        assert robot.reachable(mesh.vertices, margin=margin - 1e-6).all()
    assert (mesh.vertices[:, 2] <= z_max + 1e-6).all()
    # Closed: every edge is shared by exactly two triangles.
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all()


@pytest.mark.slow
def test_volume_mesh_encloses_the_reachable_points():
    """Sampled reachable points lie within the mesh's bounding box (nothing is cut off)."""
    robot, margin, z_max = THESIS_DELTA, 0.002, -0.06
    mesh = reachable_volume(robot, margin, z_max)
    rng = np.random.default_rng(7)
    points = rng.uniform([-0.4, -0.4, -0.45], [0.4, 0.4, 0.0], size=(200_000, 3))
    inside = points[volume_field(robot, points, margin, z_max) <= 0]
    assert len(inside) > 1000
    lo, hi = mesh.vertices.min(0), mesh.vertices.max(0)
    assert (inside >= lo - 1e-9).all() and (inside <= hi + 1e-9).all()

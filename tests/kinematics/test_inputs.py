"""Documented behaviour for bad input: non-finite values, wrong shapes, bad geometry."""

import math

import numpy as np
import pytest

from kinematics import THESIS_DELTA, InvalidGeometryError, LinearDelta, RotaryDelta, ShapeError


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_points_are_not_ok_single_and_batch(bad):
    single = THESIS_DELTA.ik([0.0, bad, -0.2])
    assert not single.ok and np.isnan(single.joints).all()
    batch = THESIS_DELTA.ik([[0.0, 0.0, -0.2], [bad, 0.0, -0.2]])
    assert batch.ok.tolist() == [True, False]
    assert np.isnan(batch.joints[1]).all() and np.isfinite(batch.joints[0]).all()
    assert not THESIS_DELTA.fk([bad, 0.0, 0.0]).ok
    assert not THESIS_DELTA.reachable([bad, 0.0, -0.2])


def test_unreachable_points_are_not_ok_and_nan():
    joints, ok = THESIS_DELTA.ik([[1.0, 0.0, -0.2], [0.0, 0.0, -0.25]])
    assert ok.tolist() == [False, True]
    assert np.isnan(joints[0]).all()


def test_fk_without_intersection_is_not_ok():
    points, ok = THESIS_DELTA.fk([0.0, 0.0, 3.0])
    assert not ok and np.isnan(points).all()


@pytest.mark.parametrize("shape", [(), (1,), (0,), (4,), (3, 1, 2)])
def test_batch_shapes_are_preserved(shape):
    points = np.broadcast_to([0.01, -0.02, -0.24], (*shape, 3))
    joints, ok = THESIS_DELTA.ik(points)
    assert joints.shape == (*shape, 3) and ok.shape == shape
    back, back_ok = THESIS_DELTA.fk(joints)
    assert back.shape == (*shape, 3) and back_ok.shape == shape
    assert THESIS_DELTA.jacobian(joints).shape == (*shape, 3, 3)
    assert THESIS_DELTA.h(points).shape == (*shape, 3)
    assert THESIS_DELTA.reachable(points).shape == shape


@pytest.mark.parametrize("bad", [[0.0, 0.0], [[1, 2, 3, 4]], 5.0, "abc", [[1, 2], [3, 4]]])
def test_wrong_shapes_name_the_argument(bad):
    with pytest.raises(ShapeError, match="points"):
        THESIS_DELTA.ik(bad)
    with pytest.raises(ShapeError, match="joints"):
        THESIS_DELTA.fk(bad)


def test_non_numeric_single_point_names_the_argument():
    with pytest.raises(ShapeError, match="points"):
        THESIS_DELTA.ik(["a", 0.0, 0.0])


def test_near_that_does_not_broadcast_names_near():
    with pytest.raises(ShapeError, match="near"):
        THESIS_DELTA.ik(np.zeros((4, 3)), near=np.zeros((2, 3)))


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"L": 0.3, "l": 0.2, "R": 0.08, "r": 0.03}, "l"),
        ({"L": -0.1, "l": 0.2, "R": 0.08, "r": 0.03}, "L"),
        ({"L": 0.1, "l": 0.2, "R": math.nan, "r": 0.03}, "R"),
        ({"L": 0.1, "l": 0.2, "R": 0.08, "r": 0.09}, "r"),
        ({"L": 0.1, "l": 0.2, "R": 0.08, "r": -0.01}, "r"),
    ],
)
def test_invalid_rotary_geometry_names_the_value(kwargs, name):
    with pytest.raises(InvalidGeometryError, match=f"^{name} ="):
        RotaryDelta(**kwargs)


def test_invalid_linear_geometry_names_the_value():
    with pytest.raises(InvalidGeometryError, match="incline"):
        LinearDelta(l=0.2, R=0.1, r=0.03, incline=2.0)
    with pytest.raises(InvalidGeometryError, match="^r ="):
        LinearDelta(l=0.2, R=0.1, r=0.1)


def test_geometry_is_frozen_and_hashable():
    with pytest.raises(AttributeError):
        THESIS_DELTA.L = 0.2  # type: ignore[misc]
    assert RotaryDelta(L=0.1558, l=0.2430, R=0.0844, r=0.038) == THESIS_DELTA
    assert THESIS_DELTA.Rbar == pytest.approx(0.0464)
    assert hash(THESIS_DELTA) == hash(RotaryDelta(L=0.1558, l=0.2430, R=0.0844, r=0.038))

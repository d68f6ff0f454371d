"""Hypothesis strategies: Delta geometries, joints and batch shapes."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st

from kinematics import THESIS_DELTA, LinearDelta, PerLegRotaryDelta, RotaryDelta

BATCH_SHAPES = st.sampled_from([(), (1,), (5,), (3, 1, 2)])


@st.composite
def rotary_deltas(draw) -> RotaryDelta:
    """The thesis robot or a random usable rotary Delta (l > L, r < R)."""
    if draw(st.booleans()):
        return THESIS_DELTA
    L = draw(st.floats(0.05, 0.3))
    l = L * draw(st.floats(1.2, 3.0))
    R = draw(st.floats(0.03, 0.2))
    r = R * draw(st.floats(0.0, 0.9))
    return RotaryDelta(L=L, l=l, R=R, r=r)


@st.composite
def linear_deltas(draw) -> LinearDelta:
    """Vertical towers (the printer case) or inclined rails."""
    R = draw(st.floats(0.05, 0.3))
    r = R * draw(st.floats(0.0, 0.6))
    l = (R - r) * draw(st.floats(1.5, 4.0))
    incline = draw(st.sampled_from([math.pi / 2, math.radians(60), math.radians(35)]))
    return LinearDelta(l=l, R=R, r=r, incline=incline)


def joint_range(robot) -> tuple[float, float]:
    """A joint range that covers the useful workspace of ``robot``."""
    if isinstance(robot, RotaryDelta):
        return -0.6, 1.5
    return -robot.l, robot.l


@st.composite
def robot_and_joints(draw, kind: str = "any", shape=None):
    """(robot, joints shaped shape + (3,)) for either robot type."""
    if kind == "rotary" or (kind == "any" and draw(st.booleans())):
        robot = draw(rotary_deltas())
    else:
        robot = draw(linear_deltas())
    shape = draw(BATCH_SHAPES) if shape is None else shape
    low, high = joint_range(robot)
    seed = draw(st.integers(0, 2**32 - 1))
    joints = np.random.default_rng(seed).uniform(low, high, size=(*shape, 3))
    return robot, joints


@st.composite
def per_leg_deltas(draw) -> PerLegRotaryDelta:
    """A rotary Delta (rotary_deltas) built wrong the ways real ones are: each leg's L, l,
    R, r off by up to 3 %, its base angle by up to 3 deg, a joint offset up to 6 deg."""
    base = draw(rotary_deltas())
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)

    def scaled(value: float) -> tuple[float, float, float]:
        return tuple(value * (1.0 + rng.uniform(-0.03, 0.03, 3)))  # type: ignore[return-value]

    L = scaled(base.L)
    l = tuple(max(a, b * 1.05) for a, b in zip(scaled(base.l), L, strict=True))
    R = scaled(base.R)
    r = tuple(min(a, b) for a, b in zip(scaled(base.r), R, strict=True))
    angles = np.radians([0.0, 120.0, 240.0]) + np.radians(rng.uniform(-3.0, 3.0, 3))
    return PerLegRotaryDelta(
        L=L, l=l, R=R, r=r,
        joint_offsets_rad=tuple(np.radians(rng.uniform(-6.0, 6.0, 3))),
        angles_rad=tuple(angles),
    )  # fmt: skip


@st.composite
def per_leg_and_joints(draw, shape=None):
    """(per-leg robot, joints shaped shape + (3,)) over the rotary joint range."""
    robot = draw(per_leg_deltas())
    shape = draw(BATCH_SHAPES) if shape is None else shape
    seed = draw(st.integers(0, 2**32 - 1))
    joints = np.random.default_rng(seed).uniform(-0.6, 1.5, size=(*shape, 3))
    return robot, joints

"""Pure NumPy kinematics of rotary and linear Delta robots.

SI units everywhere. Base frame: origin at the base centre in the plane of the
actuated joint axes, z up, x towards leg 1, legs at 0, 120, 240 deg; the platform
works at z < 0. Arrays are shaped (*batch, 3) and broadcast; a single point in gives a
single point out.
"""

from .errors import (
    DeltaError,
    InvalidGeometryError,
    NonFiniteError,
    PoseError,
    ShapeError,
    UnreachableError,
)
from .linear import LinearDelta
from .per_leg import PerLegRotaryDelta
from .pose import Pose, base_to_world, unit_quaternion, world_to_base
from .results import FKResult, IKResult, LegPoints, Projection
from .rotary import THESIS_DELTA, RotaryDelta
from .tool import Tool

__all__ = [
    "THESIS_DELTA",
    "DeltaError",
    "FKResult",
    "IKResult",
    "InvalidGeometryError",
    "LegPoints",
    "LinearDelta",
    "NonFiniteError",
    "PerLegRotaryDelta",
    "Pose",
    "PoseError",
    "Projection",
    "RotaryDelta",
    "ShapeError",
    "Tool",
    "UnreachableError",
    "base_to_world",
    "unit_quaternion",
    "world_to_base",
]

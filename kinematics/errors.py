"""Exceptions of the kinematics package.

Batch paths never raise for an unreachable point: they return an ``ok`` mask.
These exceptions are for the few places where raising is the honest answer:
a geometry that cannot be a Delta, an array of the wrong shape, a pose that is
not a pose, and a scalar request that has no solution.
"""


class DeltaError(Exception):
    """Base class of every error raised by :mod:`kinematics`."""


class InvalidGeometryError(DeltaError, ValueError):
    """A geometry parameter is outside its valid range (the message names it)."""


class ShapeError(DeltaError, ValueError):
    """An array argument has the wrong shape or is not numeric (the message names it)."""


class PoseError(DeltaError, ValueError):
    """A pose is not finite or its quaternion is not a unit quaternion."""


class UnreachableError(DeltaError):
    """No reachable point or joint solution exists for a scalar request."""


class NonFiniteError(DeltaError, ValueError):
    """An argument that must be finite holds NaN or inf (the message names it)."""

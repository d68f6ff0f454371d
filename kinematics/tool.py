"""The tool point: a fixed offset from the platform centre, optionally on a 4th wrist axis.

The platform keeps its orientation (the parallelograms see to that), so a tool tip is
the platform centre plus a constant vector: the paper's l_E along z (003, eq. 2-4),
generalised to any offset. A wrist (theta_4 = phi, paper section 2) turns the tool
about the platform's z axis, which turns the offset with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._arrays import as_vectors
from .errors import DeltaError, NonFiniteError


@dataclass(frozen=True)
class Tool:
    """Tool tip relative to the platform centre.

    Attributes:
        offset_m: tip position in the platform frame at phi = 0 [m], e.g. (0, 0, -0.05)
            for a 5 cm tool pointing down.
        wrist: True when a 4th axis turns the tool about z by phi [rad].
    """

    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    wrist: bool = False
    _offset: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        offset = as_vectors(self.offset_m, "offset_m")
        if offset.shape != (3,) or not np.isfinite(offset).all():
            raise NonFiniteError(f"offset_m: expected three finite numbers, got {self.offset_m!r}")
        object.__setattr__(self, "offset_m", tuple(float(v) for v in offset))
        object.__setattr__(self, "_offset", offset)

    def _rotated_offset(self, phi: Any) -> np.ndarray:
        if isinstance(phi, (int, float)):  # the control tick's case: no NumPy per call
            return self._rotated_offset_scalar(float(phi))
        if not self.wrist:
            if np.any(np.asarray(phi) != 0.0):
                raise DeltaError("phi: this tool has no wrist axis (Tool(wrist=True) to add one)")
            return self._offset
        angle = np.asarray(phi, dtype=np.float64)
        c, s = np.cos(angle), np.sin(angle)
        ox, oy, oz = self._offset
        return np.stack([c * ox - s * oy, s * ox + c * oy, np.broadcast_to(oz, c.shape)], -1)

    def _rotated_offset_scalar(self, phi: float) -> np.ndarray:
        if not self.wrist:
            if phi != 0.0:
                raise DeltaError("phi: this tool has no wrist axis (Tool(wrist=True) to add one)")
            return self._offset
        c, s = math.cos(phi), math.sin(phi)
        ox, oy, oz = self.offset_m
        return np.array([c * ox - s * oy, s * ox + c * oy, oz])

    def tip(self, platform_points: Any, phi: Any = 0.0) -> np.ndarray:
        """Tool tip [m] for platform centres (*, 3) and wrist angles phi (*) [rad]."""
        return as_vectors(platform_points, "platform_points") + self._rotated_offset(phi)

    def platform(self, tip_points: Any, phi: Any = 0.0) -> np.ndarray:
        """Platform centre [m] that puts the tool tip at ``tip_points`` (*, 3)."""
        return as_vectors(tip_points, "tip_points") - self._rotated_offset(phi)

    @property
    def length_m(self) -> float:
        """Distance from the platform centre to the tip [m]."""
        return math.hypot(*self.offset_m)

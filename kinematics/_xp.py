"""Math backends: every formula is written once and runs on NumPy columns or Python floats.

Single-point calls are what a 200 Hz control tick pays for, and NumPy's per-call
overhead on (3,) arrays (~15-35 us) dwarfs the arithmetic. Passing ``FLOATS`` runs the
same formula on plain floats (~1-3 us); ``ARRAYS`` runs it on whole columns.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np


def _sqrt_or_nan(value: float) -> float:
    return math.sqrt(value) if value >= 0.0 else math.nan


def _half_angle(num: float, den: float) -> float:
    """2 atan(num / den) on floats, den == 0 giving +-pi like NumPy's 1/0 = inf."""
    return 2.0 * math.atan2(num, den) if den >= 0.0 else 2.0 * math.atan2(-num, -den)


def _half_angle_array(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    return 2.0 * np.arctan(num / den)


ARRAYS = SimpleNamespace(
    sqrt=np.sqrt,
    cos=np.cos,
    sin=np.sin,
    copysign=np.copysign,
    half_angle=_half_angle_array,
    where=np.where,
)

FLOATS = SimpleNamespace(
    sqrt=_sqrt_or_nan,
    cos=math.cos,
    sin=math.sin,
    copysign=math.copysign,
    half_angle=_half_angle,
    where=lambda cond, a, b: a if cond else b,
)

# Leg directions at alpha = 0, 120, 240 deg, exact (math.cos(2 pi / 3) is off by 2 ulp).
_S3 = math.sqrt(3.0) / 2.0
LEG_COS = (1.0, -0.5, -0.5)
LEG_SIN = (0.0, _S3, -_S3)
LEG_ANGLES_RAD = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)

"""Argument checks shared by the kinematics: shapes, dtypes and broadcasting."""

from __future__ import annotations

import numpy as np

from .errors import ShapeError


def as_vectors(value: object, name: str, size: int = 3) -> np.ndarray:
    """Return ``value`` as a float64 array shaped ``(*batch, size)``.

    Raises:
        ShapeError: when ``value`` is not numeric or its last axis is not ``size``.
    """
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{name}: expected numbers shaped (..., {size}), got {value!r}") from exc
    if array.ndim == 0 or array.shape[-1] != size:
        raise ShapeError(f"{name}: expected shape (..., {size}), got {array.shape}")
    return array


def is_scalar_triple(value: object) -> bool:
    """True for one 3-vector (a length-3 list/tuple of numbers or a (3,) array)."""
    if isinstance(value, np.ndarray):
        return value.shape == (3,)
    return (
        isinstance(value, (tuple, list))
        and len(value) == 3
        and not isinstance(value[0], (tuple, list, np.ndarray))
    )


def triple_floats(value: object, name: str) -> tuple[float, float, float]:
    """Three Python floats from a scalar triple (the fast path of single-point calls)."""
    seq = value.tolist() if isinstance(value, np.ndarray) else value
    try:
        return float(seq[0]), float(seq[1]), float(seq[2])  # type: ignore[index]
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{name}: expected three numbers, got {value!r}") from exc

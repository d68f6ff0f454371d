"""Joint/measurement pairs as CSV: what a calibration collected, or data from elsewhere.

Columns (a header row, SI units): ``q0_rad, q1_rad, q2_rad`` (the joint values the
controller reads), ``x_m, y_m, z_m`` (the platform measured in the measurement frame) and
an optional ``set`` ("fit" or "holdout"). Without ``set``, every fourth row is held out.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.calibration.fit import CalibrationError

JOINTS = ("q0_rad", "q1_rad", "q2_rad")
MEASURED = ("x_m", "y_m", "z_m")
HOLDOUT_EVERY = 4


@dataclass(frozen=True)
class Pairs:
    """joints (N, 3) [rad], measured (N, 3) [m], with the ``holdout`` last rows held out."""

    joints: np.ndarray
    measured: np.ndarray
    holdout: int


def write_pairs(path: str | Path, joints: np.ndarray, measured: np.ndarray, holdout: int) -> None:
    """Write pairs (the last ``holdout`` rows marked "holdout") to ``path``."""
    n = len(joints)
    with open(path, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow([*JOINTS, *MEASURED, "set"])
        for k in range(n):
            kind = "holdout" if k >= n - holdout else "fit"
            writer.writerow(
                [*map(repr, map(float, joints[k])), *map(repr, map(float, measured[k])), kind]
            )


def read_pairs(path: str | Path) -> Pairs:
    """The pairs in a CSV file, held-out rows last.

    Raises:
        CalibrationError: naming the file, line and column of a missing column or a value
            that is not a finite number, or a ``set`` other than fit/holdout.
    """
    try:
        with open(path, newline="") as file:
            rows = list(csv.DictReader(file))
            columns = set(rows[0]) if rows else set()
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"from_csv: cannot read {path}: {exc}") from None
    missing = [c for c in (*JOINTS, *MEASURED) if c not in columns]
    if not rows or missing:
        raise CalibrationError(f"from_csv: {path} has no rows or lacks columns {missing}")
    values = np.empty((len(rows), 6))
    held = np.zeros(len(rows), dtype=bool)
    for k, row in enumerate(rows):
        line = k + 2  # the header is line 1
        for j, name in enumerate((*JOINTS, *MEASURED)):
            try:
                values[k, j] = float(row[name])
            except (TypeError, ValueError):
                values[k, j] = np.nan
            if not np.isfinite(values[k, j]):
                raise CalibrationError(
                    f"from_csv: {path} line {line}: {name} = {row[name]!r} is not a finite number"
                )
        kind = (row.get("set") or "").strip()
        if "set" in columns:
            if kind not in ("fit", "holdout"):
                raise CalibrationError(
                    f"from_csv: {path} line {line}: set = {kind!r} is not fit or holdout"
                )
            held[k] = kind == "holdout"
        else:
            held[k] = k % HOLDOUT_EVERY == HOLDOUT_EVERY - 1
    order = np.concatenate([np.flatnonzero(~held), np.flatnonzero(held)])
    values = values[order]
    return Pairs(values[:, :3], values[:, 3:], int(held.sum()))

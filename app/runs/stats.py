"""Error statistics per axis, as in thesis Tables 6.1-6.3.

error = reference - measurement per sample (goal - FK for tracking, FK - external for
validation). Mean, RMSE, population standard deviation (ddof = 0, so RMSE^2 = mean^2 +
std^2 exactly), largest |error|, and the share of samples under 1 cm and under 1 mm.
"""

from __future__ import annotations

from typing import Any

import numpy as np

AXES = ("x", "y", "z")


def axis_stats(error: np.ndarray) -> dict[str, float]:
    """Statistics of one axis' errors (N,) [m]; NaN samples are left out."""
    values = np.asarray(error, dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return {
            key: float("nan")
            for key in (
                "mean_m",
                "rmse_m",
                "std_m",
                "max_abs_m",
                "share_under_1cm",
                "share_under_1mm",
            )
        }
    magnitude = np.abs(values)
    return {
        "mean_m": float(values.mean()),
        "rmse_m": float(np.sqrt(np.mean(values**2))),
        "std_m": float(values.std(ddof=0)),
        "max_abs_m": float(magnitude.max()),
        "share_under_1cm": float(np.mean(magnitude < 0.01)),
        "share_under_1mm": float(np.mean(magnitude < 0.001)),
    }


def error_stats(
    reference: np.ndarray, measured: np.ndarray, mask: np.ndarray | None = None
) -> dict[str, Any]:
    """Per-axis statistics of ``reference - measured`` (N, 3), over ``mask`` (N,) if given."""
    error = np.asarray(reference, dtype=np.float64) - np.asarray(measured, dtype=np.float64)
    if mask is not None:
        error = error[np.asarray(mask, dtype=bool)]
    result: dict[str, Any] = {axis: axis_stats(error[:, i]) for i, axis in enumerate(AXES)}
    result["samples"] = int(len(error))
    return result


def window_mask(times_s: np.ndarray, start_s: float | None, end_s: float | None) -> np.ndarray:
    """Samples with start_s <= t <= end_s (either bound may be None)."""
    times = np.asarray(times_s)
    mask = np.ones(times.shape, dtype=bool)
    if start_s is not None:
        mask &= times >= start_s
    if end_s is not None:
        mask &= times <= end_s
    return mask


def line_stats(lines: np.ndarray, error: np.ndarray) -> list[dict[str, Any]]:
    """Tracking error per G-code program line: for each line in ``lines`` (N,) (None or
    NaN: no line) in the order first met, its sample count, the RMSE of the error's
    magnitude sqrt(mean |e|^2) and its largest magnitude max |e| [m], from ``error``
    (N, 3) [m]; samples with a NaN error are left out."""
    labels = np.asarray([np.nan if v is None else v for v in lines], dtype=np.float64)
    magnitude = np.linalg.norm(np.asarray(error, dtype=np.float64).reshape(-1, 3), axis=1)
    keep = np.isfinite(labels) & np.isfinite(magnitude)
    labels, magnitude = labels[keep], magnitude[keep]
    order = labels[np.sort(np.unique(labels, return_index=True)[1])]
    out = []
    for line in order:
        values = magnitude[labels == line]
        out.append(
            {
                "line": int(line),
                "samples": int(values.size),
                "rmse_m": float(np.sqrt(np.mean(values**2))),
                "max_m": float(values.max()),
            }
        )
    return out


def angle_stats(error_rad: np.ndarray, mask: np.ndarray | None = None) -> dict[str, Any]:
    """Statistics of angle errors (N,) [rad], already wrapped, over ``mask`` (N,) if given;
    NaN samples are left out: mean, RMSE and largest magnitude [rad], and the count."""
    values = np.asarray(error_rad, dtype=np.float64)
    if mask is not None:
        values = values[np.asarray(mask, dtype=bool)]
    values = values[np.isfinite(values)]
    if values.size == 0:
        nan = float("nan")
        return {"mean_rad": nan, "rmse_rad": nan, "max_abs_rad": nan, "samples": 0}
    return {
        "mean_rad": float(np.mean(values)),
        "rmse_rad": float(np.sqrt(np.mean(values**2))),
        "max_abs_rad": float(np.max(np.abs(values))),
        "samples": int(values.size),
    }

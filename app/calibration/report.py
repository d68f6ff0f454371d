"""The calibration's report: residuals per pose before and after the fit (a PNG)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display on a server

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from app.calibration.fit import FitResult  # noqa: E402
from app.calibration.probe import ProbeResult  # noqa: E402


def write_report(path: str | Path, result: FitResult, title: str) -> None:
    """Bars of each pose's 3D residual [mm], current model vs the fit; held-out poses shaded."""
    before = np.linalg.norm(result.residuals_before, axis=1) * 1e3
    after = np.linalg.norm(result.residuals_after, axis=1) * 1e3
    n = len(before)
    first_held = n - result.holdout
    figure, axis = plt.subplots(figsize=(10, 4.5))
    poses = np.arange(1, n + 1)
    axis.bar(
        poses - 0.2,
        before,
        0.4,
        label=_label("current model", result.rmse_before_m, result.holdout_before_m),
        color="tab:red",
    )
    axis.bar(
        poses + 0.2,
        after,
        0.4,
        label=_label("calibrated", result.rmse_after_m, result.holdout_rmse_m),
        color="tab:green",
    )
    axis.axvspan(first_held + 0.5, n + 0.5, color="0.9", zorder=0, label="held-out poses")
    axis.set_xlabel("pose")
    probe = isinstance(result, ProbeResult)  # heights only
    axis.set_ylabel("|FK z - plate z| at the touch [mm]" if probe else "|FK - measured| [mm]")
    axis.set_title(title)
    axis.legend(loc="upper right", fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _label(name: str, fit_m: float, held_m: float) -> str:
    return f"{name} (RMSE {fit_m * 1e3:.2f} mm fit, {held_m * 1e3:.2f} mm held out)"

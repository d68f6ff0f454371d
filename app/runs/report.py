"""A run's report figure in the thesis's layout (Fig. 6.2-6.4): per axis, goal and measured
position on top and the error underneath, with the statistics table beside the title."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: no display on a server

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from app.runs.stats import AXES  # noqa: E402


def write_report(
    path: Path,
    times_s: np.ndarray,
    goal: np.ndarray,
    measured: np.ndarray,
    stats: dict[str, Any],
    title: str,
) -> None:
    """Save the PNG: 3 columns (x, y, z), rows: position [mm] and error [mm] over time [s]."""
    figure, axes = plt.subplots(
        2, 3, figsize=(15, 6.5), sharex=True, gridspec_kw={"height_ratios": [2, 1]}
    )
    for i, name in enumerate(AXES):
        top, bottom = axes[0, i], axes[1, i]
        top.plot(times_s, goal[:, i] * 1e3, label="goal", color="tab:blue", linewidth=1.2)
        top.plot(
            times_s, measured[:, i] * 1e3, label="measured (FK)", color="tab:orange", linewidth=1.0
        )
        top.set_ylabel(f"{name} [mm]")
        top.grid(alpha=0.3)
        bottom.plot(times_s, (goal[:, i] - measured[:, i]) * 1e3, color="tab:red", linewidth=0.8)
        bottom.set_ylabel(f"{name} error [mm]")
        bottom.set_xlabel("time [s]")
        bottom.grid(alpha=0.3)
        axis = stats.get(name, {})
        top.set_title(
            f"{name}: RMSE {axis.get('rmse_m', float('nan')) * 1e3:.2f} mm, "
            f"mean {axis.get('mean_m', float('nan')) * 1e3:.2f} mm, "
            f"max {axis.get('max_abs_m', float('nan')) * 1e3:.2f} mm",
            fontsize=10,
        )
    axes[0, 0].legend(loc="upper right", fontsize=8)
    figure.suptitle(title)
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)

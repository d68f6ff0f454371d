"""PNG figures of the design tools (matplotlib, Agg backend: no display needed).

Thesis Fig. 4.2-4.5 style: workspace sections with the dexterity (1/cond J) and the
power of point sum |h_i| as maps, and the desired box over the workspace.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; must precede pyplot

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from kinematics import RotaryDelta  # noqa: E402
from kinematics.analysis import Section, section  # noqa: E402

_AXES = {
    "xy": ("x [mm]", "y [mm]", "z"),
    "xz": ("x [mm]", "z [mm]", "y"),
    "yz": ("y [mm]", "z [mm]", "x"),
}


def section_map(cut: Section, path: Path, quantity: str = "dexterity", title: str = "") -> Path:
    """Draw one section map to ``path`` (PNG): dexterity or log10 power of point."""
    fig, ax = plt.subplots(figsize=(6.0, 5.0), dpi=110)
    extent = (cut.u[0] * 1e3, cut.u[-1] * 1e3, cut.v[0] * 1e3, cut.v[-1] * 1e3)
    if quantity == "dexterity":
        image = ax.imshow(
            cut.dexterity, origin="lower", extent=extent, cmap="viridis", vmin=0.0, vmax=1.0
        )
        label = "dexterity 1/cond(J)"
    else:
        with np.errstate(divide="ignore"):
            image = ax.imshow(
                np.log10(cut.power_of_point), origin="lower", extent=extent, cmap="magma"
            )
        label = "log10 power of point sum|h_i| [m^4]"
    ax.contour(
        cut.u * 1e3,
        cut.v * 1e3,
        cut.reachable.astype(float),
        levels=[0.5],
        colors="white",
        linewidths=1.0,
    )
    fig.colorbar(image, ax=ax, label=label)
    xlabel, ylabel, normal = _AXES[cut.plane]
    ax.set(xlabel=xlabel, ylabel=ylabel, aspect="equal")
    ax.set_title(title or f"{label}, section {normal} = {cut.level * 1e3:.0f} mm", fontsize=9)
    return _save(fig, path)


def box_over_section(
    cut: Section, lower: np.ndarray, upper: np.ndarray, path: Path, title: str, witness=None
) -> Path:
    """An x-z section's reachable set with the desired box (and a witness point) drawn on."""
    fig, ax = plt.subplots(figsize=(6.0, 5.0), dpi=110)
    extent = (cut.u[0] * 1e3, cut.u[-1] * 1e3, cut.v[0] * 1e3, cut.v[-1] * 1e3)
    ax.imshow(cut.dexterity, origin="lower", extent=extent, cmap="viridis", vmin=0, vmax=1)
    ax.contour(
        cut.u * 1e3,
        cut.v * 1e3,
        cut.reachable.astype(float),
        levels=[0.5],
        colors="black",
        linewidths=1.0,
    )
    u0, v0 = lower[0] * 1e3, lower[2] * 1e3
    width, height = (upper[0] - lower[0]) * 1e3, (upper[2] - lower[2]) * 1e3
    ax.add_patch(plt.Rectangle((u0, v0), width, height, fill=False, edgecolor="red", lw=1.5))
    if witness is not None:
        ax.plot(witness[0] * 1e3, witness[2] * 1e3, "rx", ms=8, label="outside (witness)")
        ax.legend(loc="lower right", fontsize=8)
    ax.set(xlabel="x [mm]", ylabel="z [mm]", aspect="equal")
    ax.set_title(title, fontsize=9)
    return _save(fig, path)


def _save(fig: plt.Figure, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def workspace_maps(delta: RotaryDelta, out: Path, sections_z_m: list[float]) -> list[Path]:
    """Dexterity on the x-z plane, then dexterity and power of point on each x-y section."""
    paths = [section_map(section(delta, "xz", 0.0), out / "dexterity_xz.png")]
    for z in sections_z_m:
        cut = section(delta, "xy", z)
        name = f"z{abs(z) * 1e3:.0f}mm"
        paths.append(section_map(cut, out / f"dexterity_xy_{name}.png"))
        paths.append(
            section_map(cut, out / f"power_of_point_xy_{name}.png", quantity="power_of_point")
        )
    return paths

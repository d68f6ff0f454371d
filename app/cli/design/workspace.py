"""``deltadash design workspace``: volume, largest box and cylinder, section maps."""

from __future__ import annotations

import argparse
from pathlib import Path

from app.cli.design.arguments import common, emit, robot_from
from app.cli.numbers import number
from kinematics import RotaryDelta
from kinematics.analysis import largest_region, workspace_volume


def add_parser(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "workspace",
        help="volume, largest box/cylinder, dexterity maps",
        description="Reachable volume below the base, the largest box and "
        "cylinder of given proportions at a given height (certified), and "
        "PNG maps of dexterity 1/cond(J) and power of point over sections "
        "(thesis Fig. 4.2-4.5).",
    )
    p.add_argument(
        "--z",
        type=number,
        default=-0.1903,
        help="height of the region's centre (or top, --anchor top) [m] (-0.1903)",
    )
    p.add_argument("--anchor", choices=["centre", "top"], default="centre")
    p.add_argument(
        "--proportions",
        type=number,
        nargs=3,
        default=[1.0, 1.0, 1.0],
        help="box edges x:y:z; the cylinder uses diameter x : height z (1 1 1)",
    )
    p.add_argument("--cells", type=int, default=120, help="grid cells per axis for the volume")
    p.add_argument(
        "--sections",
        type=number,
        nargs="*",
        default=[-0.15, -0.25, -0.35],
        help="z of the x-y sections [m]",
    )
    p.add_argument("--out", type=Path, help="folder for the PNG figures")
    common(p)
    p.set_defaults(handler=_workspace)


def _workspace(args: argparse.Namespace) -> int:
    delta = robot_from(args)
    volume = workspace_volume(delta, cells_per_axis=args.cells)
    fits = {
        shape: largest_region(delta, tuple(args.proportions), args.z, args.anchor, shape)
        for shape in ("box", "cylinder")
    }
    figures = _figures(delta, args.out, args.sections) if args.out else []
    payload = {
        "volume_m3": volume.volume_m3,
        "volume_error_m3": volume.boundary_m3,
        "box_m": list(fits["box"].size_m),
        "box_lower_m": list(fits["box"].lower),
        "cylinder_diameter_m": fits["cylinder"].size_m[0],
        "cylinder_height_m": fits["cylinder"].size_m[2],
        "figures": [str(f) for f in figures],
    }
    box, cyl = fits["box"], fits["cylinder"]
    text = "\n".join(
        [
            f"reachable volume below the base: {volume.volume_m3 * 1e3:.2f} L "
            f"(+- {volume.boundary_m3 * 1e3:.2f} L, {volume.cell_m * 1e3:.1f} mm cells)",
            f"largest box ({args.anchor} at z = {args.z * 1e3:.1f} mm): "
            + " x ".join(f"{v * 1e3:.1f}" for v in box.size_m)
            + " mm",
            f"largest cylinder: diameter {cyl.size_m[0] * 1e3:.1f} mm, height "
            f"{cyl.size_m[2] * 1e3:.1f} mm",
            *(f"figure: {f}" for f in figures),
        ]
    )
    emit(args, payload, text)
    return 0


def _figures(delta: RotaryDelta, out: Path, sections: list[float]) -> list[Path]:
    from app.design.figures import workspace_maps  # matplotlib only when figures are asked for

    return workspace_maps(delta, out, sections)

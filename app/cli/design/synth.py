"""``deltadash design synth``: geometric synthesis and the thesis check."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from app.cli.design.arguments import common, emit
from app.cli.numbers import number
from app.cli.progress import Progress
from kinematics.synthesis import (
    THESIS_PLATFORM_RADIUS_M,
    Bounds,
    DesiredVolume,
    Problem,
    synthesize,
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "synth",
        help="smallest Delta whose workspace holds a box",
        description="Geometric synthesis (thesis eq. 4.5-4.10, Laribi's "
        "power of point) by differential evolution; the box (top face at "
        "depth H) is certified, not just its vertices; the thesis's Table "
        "4.3 design is checked on the same problem. Exit status 1 if not contained.",
    )
    p.add_argument(
        "--size",
        type=number,
        nargs=3,
        default=[0.22, 0.22, 0.22],
        help="box edges [m] (20 cm + 1 cm margin each side)",
    )
    p.add_argument(
        "--extra",
        type=number,
        nargs=3,
        action="append",
        help="extra point [m], repeatable (default 0 0 -0.075)",
    )
    b = Bounds()
    for name in ("L", "l", "Rbar", "H"):
        p.add_argument(
            f"--bounds-{name}",
            type=number,
            nargs=2,
            default=list(getattr(b, name)),
            help=f"search interval of {name} [m] (Table 4.2: {getattr(b, name)})",
        )
    p.add_argument(
        "--r",
        type=number,
        default=THESIS_PLATFORM_RADIUS_M,
        help="platform radius for the config, R = Rbar + r [m] (0.038)",
    )
    p.add_argument("--popsize", type=int, default=40, help="population per variable (40)")
    p.add_argument("--maxiter", type=int, default=300, help="generations (300)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--out",
        type=Path,
        help="folder for design.toml ([robot] for serve --config), report.md/.json, PNG",
    )
    common(p, robot=False)
    p.set_defaults(handler=_synth)


def _synth(args: argparse.Namespace) -> int:
    from app.design import report
    from app.design.synthesis_report import write_synthesis_report

    extra = tuple(tuple(e) for e in args.extra) if args.extra else ((0.0, 0.0, -0.075),)
    bounds = Bounds(*(tuple(getattr(args, f"bounds_{n}")) for n in ("L", "l", "Rbar", "H")))
    problem = Problem(DesiredVolume(tuple(args.size), extra), bounds)
    # a bar on a terminal, a line every 10 % otherwise (CI, pipes); stdout keeps the result
    with Progress(args.maxiter, "synthesis", "gen") as bar:

        def progress(generation: int, best: float) -> None:
            bar.update_to(generation, note=f"best {best:.4g}")

        start = time.perf_counter()
        result = synthesize(
            problem, popsize=args.popsize, maxiter=args.maxiter, seed=args.seed, callback=progress
        )
        seconds = time.perf_counter() - start
    payload = report.synth_payload(result, problem, seconds, args.r)
    if args.out:
        files = write_synthesis_report(args.out, result, problem, payload, args.r)
        payload["files"] = [str(p) for p in files]
    emit(args, payload, report.synth_table(payload))
    return 0 if result.contains else 1

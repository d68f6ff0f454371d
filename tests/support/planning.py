"""A RunManager over a stand-in controller at rest (no loop, no bus): plans and checks
runs exactly as the server does, for tests of the planner alone."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from app.config import load_settings
from app.control.commands import CommandContext
from app.control.owner import MotionOwner
from app.control.state import Snapshot
from app.runs.manager import RunManager

REST_M = np.array([0.0, 0.0, -0.24])


def resting_manager(folder, start_m=REST_M, **runs) -> RunManager:
    """Plans from a robot commanded and measured at ``start_m`` [m]; ``runs`` overrides
    settings.runs (e.g. max_samples)."""
    config = load_settings(runs={"folder": str(folder), **runs})
    ctx = CommandContext.from_settings(config)
    start = np.asarray(start_m, dtype=np.float64)
    snap = Snapshot(
        joints_measured_rad=ctx.robot.ik(start).joints,
        point_measured_m=start,
        point_commanded_m=start,
    )
    controller = SimpleNamespace(
        snapshot=lambda: snap,
        period_s=ctx.period_s,
        settings=config,
        gate=ctx.gate,
        model=ctx.model,
        owner=MotionOwner(),
    )
    return RunManager(controller, folder)  # type: ignore[arg-type]

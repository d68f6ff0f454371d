"""The control loop on the MuJoCo twin stepped by hand, in simulated time.

No thread, no clock but the one it advances: each :meth:`TwinLoop.step` advances the
twin's physics one loop period and runs one tick (``Controller.step``), so a test (or a
benchmark: benchmarks/contact.py) sees every tick and the twin's own truth at it (its
contact force: ``bus.measure_contact``). Commands are the control thread's functions
called between ticks (app/control/commands.py, contact_commands.py), as the thread runs
them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from app.config import Settings, load_settings
from app.control import commands
from app.control.controller import Controller
from app.control.state import Snapshot
from hardware.sim.sim_bus import SimBus, SimBusConfig
from hardware.sim.surfaces import Plate
from hardware.sim.twin import TwinConfig


class TwinLoop:
    """A controller on the twin with ``plates`` (hardware/sim/surfaces.py), ``bus``:
    SimBusConfig's other fields (e.g. current_noise_a), ``settings`` overrides as
    load_settings takes them (sections as dicts)."""

    def __init__(
        self, plates: Sequence[Plate] = (), bus: dict[str, Any] | None = None, **overrides: Any
    ) -> None:
        self.settings: Settings = load_settings(**overrides)
        tool = self.settings.tool.offset_m
        twin = TwinConfig(plates=tuple(plates), tip_offset_m=tool)
        options = {"realtime": False, "torque_on_at_start": True, **(bus or {})}
        self.bus = SimBus(SimBusConfig(twin=twin, **options))
        self.bus.connect()
        self.now_s = 0.0
        self.controller = Controller(self.settings, self.bus, "sim", clock=lambda: self.now_s)
        self.period_s = self.controller.period_s
        self.step(5)
        commands.torque_to(self.state, self.ctx, self.controller.joint_bus, True)
        self.step(100)

    @property
    def state(self) -> Any:
        return self.controller.state

    @property
    def ctx(self) -> Any:
        return self.controller.ctx

    @property
    def snapshot(self) -> Snapshot:
        return self.controller.snapshot()

    def step(self, n: int = 1, each: Callable[[TwinLoop], None] | None = None) -> None:
        """``n`` ticks, each one period of physics first; ``each(self)`` after every tick."""
        for _ in range(n):
            self.bus.advance(self.period_s)
            self.now_s += self.period_s
            self.controller.step()
            if each is not None:
                each(self)

    def run_until(
        self, done: Callable[[TwinLoop], bool], most_s: float, each: Callable | None = None
    ) -> float:
        """Tick until ``done(self)``; the simulated time it took [s]. AssertionError past
        ``most_s`` of simulated time."""
        start = self.now_s
        while not done(self):
            if self.now_s - start > most_s:
                raise AssertionError(f"not done within {most_s} s of simulated time")
            self.step(each=each)
        return self.now_s - start

    def move_to(self, point_m: Sequence[float], most_s: float = 5.0) -> None:
        """A move to ``point_m`` [m] and the arm at rest there."""
        commands.move(self.state, self.ctx, np.asarray(point_m, dtype=float), None, False)
        self.run_until(lambda loop: loop.state.source is None, most_s)
        self.step(int(0.3 / self.period_s))

    def close(self) -> None:
        self.bus.disconnect()

"""The simulated robot: a MuJoCo twin of the Delta driven by physical XM430-W210 models.

- `mjcf.build_mjcf`: the MJCF of any RotaryDelta and `masses.DeltaMasses`.
- `xm430.Xm430`: firmware position loop, PWM, DC motor, heat and overload.
- `twin.DeltaTwin`: mechanism and servos stepped together (no wall clock).
- `sim_bus.SimBus`: the twin as a `hardware.bus.ServoBus`, stepped by the caller or a thread.
- `process_bus.ProcessSimBus`: a `SimBus` in its own process (the server's backend).
- `twin_shaft_motion.TwinMotionModel`: the twin as the emulator's `MotionModel`.
"""

from hardware.base_motion import BaseMotion
from hardware.sim.masses import THESIS_MASSES, DeltaMasses, gravity_torques
from hardware.sim.process_bus import ProcessSimBus
from hardware.sim.sim_bus import SimBus, SimBusConfig
from hardware.sim.twin import DeltaTwin, TwinConfig
from hardware.sim.twin_shaft_motion import TwinMotionModel
from hardware.sim.xm430 import XM430_W210, Xm430, Xm430Params

__all__ = [
    "BaseMotion",
    "THESIS_MASSES",
    "XM430_W210",
    "DeltaMasses",
    "DeltaTwin",
    "SimBus",
    "SimBusConfig",
    "TwinConfig",
    "TwinMotionModel",
    "Xm430",
    "Xm430Params",
    "ProcessSimBus",
    "gravity_torques",
]

"""The bus protocols: every bus is a ServoBus; only the simulated ones are SimulatedBuses."""

from __future__ import annotations

from hardware.bus import ServoBus, SimulatedBus
from hardware.calibration import JointCalibration
from hardware.dynamixel.driver import DynamixelBus, DynamixelConfig
from hardware.sim import ProcessSimBus, SimBus, SimBusConfig


def test_the_simulated_buses_are_simulated_buses() -> None:
    sim = SimBus(SimBusConfig(realtime=False))
    process = ProcessSimBus(SimBusConfig())  # not connected: no child process
    for bus in (sim, process):
        assert isinstance(bus, ServoBus)
        assert isinstance(bus, SimulatedBus)


def test_the_dynamixel_bus_is_not_a_simulated_bus() -> None:
    joints = tuple(JointCalibration(servo_id) for servo_id in (1, 2, 3))
    dxl = DynamixelBus(DynamixelConfig(joints=joints, port="/dev/null"))  # never opened
    assert isinstance(dxl, ServoBus)
    assert not isinstance(dxl, SimulatedBus)

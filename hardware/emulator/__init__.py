"""The emulator room: XM430-W210 servos that speak Dynamixel Protocol 2.0 on a pty.

- `pty_transport.ServoEmulator`: the pty and its thread, bytes in and out.
- `emulated_bus.EmulatedBus`: a request packet in, reply packets out (no pty, no thread);
  `group_instructions`: its sync and bulk reads and writes.
- `emulated_servo.EmulatedServo`: one servo's instructions and injected faults;
  `memory.ServoMemory`: its control-table bytes with the e-manual's access rules.
- `stepping`: control tables to motion commands and present values back; what the shafts
  do between packets is a hardware.shaft_motion `MotionModel` (`SimpleServoModel` by
  default; the MuJoCo twin's is hardware.sim.twin_shaft_motion).
- `serve`: run one standalone until stopped (``python -m hardware.emulator``,
  ``deltadash emulate``).
"""

from hardware.emulator.emulated_bus import EmulatedBus, Outgoing
from hardware.emulator.pty_transport import ServoEmulator

__all__ = ["EmulatedBus", "Outgoing", "ServoEmulator"]

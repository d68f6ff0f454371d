"""Servo buses: the ServoBus interface, the Dynamixel driver, the emulator and the simulator."""

"""The Dynamixel room: the XM430-W210 control table as data, Protocol 2.0 framing, the SDK
link and the `DynamixelBus` driver.

Import the modules themselves (`hardware.dynamixel.driver`, `.control_table`, `.protocol`,
`.link`): this package imports nothing, so the emulator and the simulator can read the
control table without loading dynamixel-sdk or the driver that imports them.
"""

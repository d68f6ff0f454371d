"""Opening the servo bus a config asks for: simulated, emulated or real Dynamixel servos."""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass

from app.config import Settings
from app.control.sim_time import SteppedClock
from hardware.bus import ServoBus
from hardware.calibration import JointCalibration
from hardware.dynamixel.control_table import Reg
from hardware.dynamixel.driver import DynamixelBus, DynamixelConfig
from hardware.emulator import ServoEmulator
from kinematics import RotaryDelta


@dataclass(frozen=True)
class Backend:
    """An open bus and how to describe it to the operator."""

    bus: ServoBus
    kind: str  # sim | emulated | dynamixel
    description: str
    emulator: ServoEmulator | None = None  # for fault injection in tests and demos
    # simulated time (app/control/sim_time.py): the loop's clock, driven by whoever opened
    # the backend; None: the loop runs in real time
    sim_clock: SteppedClock | None = None


def _calibrations(settings: Settings) -> tuple[JointCalibration, ...]:
    """The bus's joints in bus order: the three legs, then the wrist when it is enabled."""
    return tuple(joint.calibration() for joint in settings.bus_joints())


# The emulator is software on the same machine: a loaded one can deschedule it for longer
# than the SDK's ~34 ms status timeout (sized for real servos behind a USB latency timer),
# and a reply that comes late is a missed read. Its bus waits at least this long; on
# simulated time (tests), where no deadline is real, twice that: 0.25 s still let a healthy
# servo's reply miss with two test workers beside two CPU hogs.
EMULATOR_REPLY_WAIT_S = 0.25
SIM_TIME_REPLY_WAIT_S = 0.5
EMULATOR_CONNECT_S = 5.0
# and tries: three of those waits (0.75 s) still went unanswered once in a whole suite run
# beside two CPU hogs (a gain write in test_tuning_api); an emulator gets five
EMULATOR_TRIES = 5


def _dynamixel(
    settings: Settings, port: str, emulated: bool = False, sim_time: bool = False
) -> DynamixelBus:
    hw = settings.hardware
    reply_wait_s = SIM_TIME_REPLY_WAIT_S if sim_time else EMULATOR_REPLY_WAIT_S
    config = DynamixelConfig(
        joints=_calibrations(settings),
        port=port,
        baudrate=hw.baud,
        max_tries=max(hw.max_tries, EMULATOR_TRIES) if emulated else hw.max_tries,
        min_reply_wait_s=reply_wait_s if emulated else 0.0,
        # an emulator thread or process not yet scheduled on a loaded machine answers its
        # first pings late: a few of its reply waits are not a servo missing
        connect_timeout_s=EMULATOR_CONNECT_S if emulated else 1.0,
        # and pings after a reboot the same: 2 s is four of its sim-time reply waits
        reboot_timeout_s=EMULATOR_CONNECT_S if emulated else 2.0,
    )
    return DynamixelBus(config)


def _twin(settings: Settings, realtime: bool = True) -> ServoBus:
    """The simulated robot (hardware/sim) for this config's rotary Delta; without
    ``realtime`` an in-process `SimBus` whose physics steps only when told (`advance`)."""
    from hardware.sim import ProcessSimBus, SimBus, SimBusConfig, TwinConfig

    # built as drawn ([robot] L, l, R, r) or wrong on purpose ([hardware.sim]); never as a
    # calibration believes it is ([robot.legs], the controller's model only)
    robot = settings.robot.symmetric()
    if not isinstance(robot, RotaryDelta):
        raise ValueError("robot.type: the simulator models rotary Deltas; use backend 'emulated'")
    sim = settings.hardware.sim
    twin = TwinConfig(
        robot=robot,
        joints=_calibrations(settings),
        true_robot=sim.true_robot(robot),
        tip_offset_m=settings.tool.offset_m,
        plates=sim.build_plates(),
    )
    bus = ProcessSimBus if settings.hardware.sim_process and realtime else SimBus
    return bus(
        SimBusConfig(
            twin=twin,
            noise_std_m=sim.measurement_noise_m,
            measurement_frame_position_m=sim.measurement_frame_position_m,
            measurement_frame_rpy_rad=sim.measurement_frame_rpy_rad,
            realtime=realtime,
        )
    )


@contextlib.contextmanager
def _emulator_thread(ids: list[int], clock: SteppedClock | None = None) -> Iterator[ServoEmulator]:
    emulator = ServoEmulator(ids) if clock is None else ServoEmulator(ids, clock=clock.now)
    with emulator.lock:
        for servo in emulator.servos:  # a tuned robot's bus: no 500 us reply delay
            servo.table.set(Reg.RETURN_DELAY_TIME, 0)
    with emulator:
        yield emulator


@contextlib.contextmanager
def _emulator_process(ids: list[int]) -> Iterator[str]:
    """The emulator as its own process, like a device on the wire; yields its pty path.

    In-process it would compete for the GIL with the SDK, which polls the port while it
    waits for a reply: measured p99 tick 4.4 ms in a thread against ~1 ms in a process.
    Its servos move the MuJoCo twin, so the emulated bus is as physical as the simulator.
    """
    command = [
        sys.executable,
        "-m",
        "hardware.emulator",
        "--return-delay-us",
        "0",
        "--ids",
        ",".join(map(str, ids)),
        "--model",
        "twin",
    ]
    process = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
    )
    try:
        port = process.stdout.readline().strip() if process.stdout else ""
        if not port:
            raise RuntimeError("the servo emulator did not start")
        yield port
    finally:
        process.terminate()
        process.wait(timeout=10)


@contextlib.contextmanager
def open_backend(
    settings: Settings, emulator_in_process: bool = False, sim_time: bool = False
) -> Iterator[Backend]:
    """Connect the configured bus for the duration of the ``with`` block.

    ``emulator_in_process`` runs the emulator as a thread of this process, so tests can
    inject faults into it; the server runs it as a separate process. ``sim_time``: the
    loop runs on simulated time that moves only when driven (``Backend.sim_clock``,
    app/control/sim_time.py): the twin steps in the loop's thread, the in-process
    emulator's servos move by that clock. Raises ValueError for ``sim_time`` on real
    servos or the emulator in a process of its own.
    """
    kind = settings.hardware.backend
    clock: SteppedClock | None = None
    if sim_time:
        if kind == "dynamixel" or (kind == "emulated" and not emulator_in_process):
            raise ValueError(
                "sim_time: needs the twin (backend sim) or the emulator in this process"
            )
        clock = SteppedClock(settings.loop.rate_hz)
    ids = [joint.servo_id for joint in settings.bus_joints()]
    with contextlib.ExitStack() as stack:
        emulator: ServoEmulator | None = None
        if kind == "sim":
            bus = _twin(settings, realtime=clock is None)
            bus.connect()
            stack.callback(bus.disconnect)
            if clock is not None:
                clock.on_tick = bus.advance  # type: ignore[attr-defined]  # a SimBus
            description = "simulated robot: MuJoCo twin with XM430-W210 servo models"
            yield Backend(bus, kind, description, sim_clock=clock)
            return
        if kind == "dynamixel":
            port = settings.hardware.port
            description = f"Dynamixel servos on {port} at {settings.hardware.baud} bit/s"
        elif emulator_in_process:
            emulator = stack.enter_context(_emulator_thread(ids, clock))
            port, description = emulator.port, f"emulated XM430-W210 bus on {emulator.port}"
        else:
            port = stack.enter_context(_emulator_process(ids))
            description = f"emulated XM430-W210 bus on {port} (dynamixel-sdk)"
        bus = _dynamixel(settings, port, emulated=kind == "emulated", sim_time=clock is not None)
        bus.connect()
        stack.callback(bus.disconnect)
        yield Backend(bus, kind, description, emulator, sim_clock=clock)

"""The MuJoCo twin in its own process: the server's simulated bus.

In the server's process the twin's physics thread competed with the control loop for the
GIL a few hundred times a second (docs/performance.md, "Control loop"). Here a child
process owns a `SimBus` and steps it against the wall clock, 2 ms at a time; the loop's
hot path never waits for it:

- after every step the child publishes the joint state, its simulated time, the
  platform position and the twin's contact force into shared memory; `read_state` copies
  the latest frame (at most one 2 ms step old on a quiet machine, where a real bus read is
  a fraction of a millisecond old by the time it arrives). A starved child publishes
  late: the state then carries the same `sim_time_s` as the previous read, so the loop
  knows it is stale (app/control/safety.py `FeedbackFreshness`) instead of taking a
  frozen arm for a lagging one;
- `write_goal` validates the goal here (the same `goal_ticks` as every bus) and leaves it
  in shared memory; the child applies it before its next step;
- everything else (torque, gains, profile, reboot, base motion) is a request over a pipe
  that the child answers between steps, raising the same errors as `SimBus`.

The child exits when the parent closes the pipe or dies.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import signal
import threading
import time
from collections.abc import Sequence
from dataclasses import replace
from multiprocessing.connection import Connection
from multiprocessing.shared_memory import SharedMemory
from typing import Any

import numpy as np

from hardware.base_motion import BaseMotion
from hardware.bus import READINGS, BusStats, JointState, PositionGains, ServoInfo
from hardware.calibration import goal_ticks
from hardware.dynamixel.control_table import OperatingMode, hardware_error_names
from hardware.errors import BusError, NotConnectedError
from hardware.sim.sim_bus import MAX_CATCH_UP_S, SimBus, SimBusConfig, external_measurement
from hardware.sim.surfaces import TwinContact

STEP_S = 2e-3  # physics chunk = the most the published state lags (1 ms: 28 % of a core, not 22)
LOCK_TIMEOUT_S = 0.05
START_TIMEOUT_S = 60.0
REPLY_TIMEOUT_S = 10.0
# A frame this old means the child is dead or stuck: the read fails. A starved child (a
# loaded machine) publishes late; its frames carry their simulated time, and the loop marks
# a state whose simulated time did not advance as stale (it is not a bus fault here).
STALE_S = 2.0

# shared frame: state written by the child, goal written by the parent (float64 slots);
# room for four servos per column (three legs and a wrist), a bus uses its first n; one
# column per servo reading (hardware/bus.py READINGS), then the flags
_W = 4
_COLUMNS = ("position_rad", *READINGS, "moving", "errors", "torque")
_COLUMN = {name: slice(_W * k, _W * k + _W) for k, name in enumerate(_COLUMNS)}
_POS, _MOVING, _ERR, _TORQUE = (_COLUMN[c] for c in ("position_rad", "moving", "errors", "torque"))
_STAMP = _W * len(_COLUMNS)
_PLATFORM = slice(_STAMP + 1, _STAMP + 4)
_GOAL_SEQ, _GOAL, _SIM_TIME = _STAMP + 4, slice(_STAMP + 5, _STAMP + 5 + _W), _STAMP + 5 + _W
# the twin's contact (hardware.sim.surfaces.TwinContact): force [N], point [m] (NaN without
# contact), in contact (1.0 / 0.0)
_CONTACT = slice(_SIM_TIME + 1, _SIM_TIME + 8)
_FRAME_SIZE = _SIM_TIME + 8


def _contact_of(values: np.ndarray) -> TwinContact:
    """The TwinContact held in the frame's contact slots (a copy, shape (7,))."""
    point = values[3:6]
    return TwinContact(
        values[:3].copy(),
        point.copy() if np.isfinite(point).all() else None,
        bool(values[6] > 0.5),
    )


def _contact_values(contact: TwinContact) -> list[float]:
    point = [np.nan] * 3 if contact.point_m is None else list(contact.point_m)
    return [*contact.force_n, *point, float(contact.in_contact)]


class ProcessSimBus:
    """ServoBus on a `SimBus` in a child process (joint order = the calibrations' order)."""

    carries_load = True  # real or simulated links under gravity (the loop compensates)

    def __init__(self, config: SimBusConfig | None = None) -> None:
        self.config = replace(config or SimBusConfig(), realtime=False)  # the child paces it
        self.joints = self.config.twin.joints
        self.ids = tuple(j.servo_id for j in self.joints)
        self.n = n = len(self.ids)  # three legs, and a wrist when the twin has one
        if n > _W:
            raise ValueError(f"{n} servos: the shared frame holds at most {_W}")
        self._rng = np.random.default_rng(self.config.seed)
        self._stats = BusStats()
        self._process: mp.process.BaseProcess | None = None
        self._conn: Connection | None = None
        self._memory: SharedMemory | None = None
        self._frame: np.ndarray | None = None
        self._frame_lock: Any = None
        self._request_lock = threading.Lock()
        self._platform_at_read = np.full(3, np.nan)
        self._contact_at_read: TwinContact | None = None

    # -- ServoBus ------------------------------------------------------------------------
    @property
    def simulator_pid(self) -> int | None:
        """The simulator's process id (None before connect): a real-time loop gives it a
        real-time priority too (app/robot/realtime.py), or a station's processes could
        preempt it while it holds the shared frame's lock."""
        return None if self._process is None else self._process.pid

    def connect(self) -> None:
        self.disconnect()
        context = mp.get_context("spawn")  # never fork a process that runs threads
        self._memory = SharedMemory(create=True, size=_FRAME_SIZE * 8)
        self._frame = np.ndarray((_FRAME_SIZE,), dtype=np.float64, buffer=self._memory.buf)
        self._frame[:] = np.nan
        self._frame[_GOAL_SEQ] = 0.0
        self._frame_lock = context.Lock()
        self._conn, child_end = context.Pipe()
        self._process = context.Process(
            target=_child_main,
            args=(self.config, child_end, self._memory.name, self._frame_lock),
            name="deltadash-sim",
            daemon=True,
        )
        self._process.start()
        child_end.close()
        try:
            ready = self._conn.poll(START_TIMEOUT_S) and self._conn.recv() == "ready"
        except (EOFError, OSError):
            ready = False
        if not ready:
            self.disconnect()
            raise NotConnectedError(
                self.ids,
                "connect",
                "the simulator process did not start (a script that starts it needs an "
                "`if __name__ == '__main__':` guard: the process imports the main module)",
            )

    def disconnect(self) -> None:
        if self._conn is not None:
            with contextlib.suppress(OSError):  # the child may already be gone
                self._conn.send(None)
            self._conn.close()
            self._conn = None
        if self._process is not None:
            self._process.join(timeout=5.0)
            if self._process.is_alive():
                self._process.kill()
            self._process = None
        if self._memory is not None:
            self._frame = None
            self._memory.close()
            self._memory.unlink()
            self._memory = None

    def scan(self, ids: Sequence[int] | None = None) -> list[ServoInfo]:
        return self._call("scan", ids)

    def torque(self, enabled: bool) -> None:
        self._call("torque", enabled)

    def set_operating_mode(self, mode: OperatingMode) -> None:
        self._call("set_operating_mode", OperatingMode(mode))

    def set_goal_current(self, currents_a: Sequence[float]) -> None:
        """Goal Current per joint [A], as `SimBus.set_goal_current` (in the simulator
        process; its ValueError comes back as it is)."""
        self._call("set_goal_current", [float(c) for c in currents_a])

    def read_goal_current(self) -> list[float]:
        """Each joint's Goal Current [A] as the simulated servo holds it, in joint order."""
        return self._call("read_goal_current")

    def write_goal(self, positions_rad: Sequence[float]) -> None:
        goal_ticks(self.joints, positions_rad)  # refuse bad goals here, with the same errors
        frame = self._require_frame("sync write GOAL_POSITION")
        with self._frame_access("sync write GOAL_POSITION"):
            frame[_GOAL][: self.n] = np.asarray(positions_rad, dtype=float)
            frame[_GOAL_SEQ] += 1.0
        self._count()

    def read_state(self) -> JointState:
        instruction = "sync read MOVING..PRESENT_TEMPERATURE"
        frame = self._require_frame(instruction)
        with self._frame_access(instruction):
            values = frame.copy()
        self._count()
        if time.monotonic() - values[_STAMP] > STALE_S:  # a dead or hung child
            raise BusError(self.ids, instruction, "the simulator process stopped stepping")
        self._platform_at_read = values[_PLATFORM]
        self._contact_at_read = _contact_of(values[_CONTACT])
        n = self.n
        return JointState(
            position_rad=values[_POS][:n],
            **{name: values[_COLUMN[name]][:n] for name in READINGS},
            moving=values[_MOVING][:n] > 0.5,
            hardware_errors=tuple(hardware_error_names(int(c)) for c in values[_ERR][:n]),
            stamp_s=float(values[_STAMP]),
            sim_time_s=float(values[_SIM_TIME]),
            torque_enabled=tuple(bool(t > 0.5) for t in values[_TORQUE][:n]),
        )

    def set_profile(self, velocity_rad_s: float, acceleration_rad_s2: float) -> None:
        self._call("set_profile", velocity_rad_s, acceleration_rad_s2)

    def set_gains(self, gains: PositionGains | Sequence[PositionGains]) -> None:
        self._call("set_gains", gains)

    def read_gains(self) -> list[PositionGains]:
        return self._call("read_gains")

    def reboot(self, ids: Sequence[int] | None = None) -> None:
        self._call("reboot", ids)

    @property
    def stats(self) -> BusStats:
        return self._stats

    # -- beyond the ServoBus protocol --------------------------------------------------
    def measure_platform(self, at_last_read: bool = False) -> np.ndarray:
        """The external measurement of the platform [m], shape (3,), as
        `SimBus.measure_platform`; with ``at_last_read`` at the instant of the last read."""
        if at_last_read and np.isfinite(self._platform_at_read).all():
            true = self._platform_at_read
        else:
            frame = self._require_frame("measure platform")
            with self._frame_access("measure platform"):
                true = frame[_PLATFORM].copy()
        return external_measurement(self.config, true, self._rng)

    def measure_contact(self, at_last_read: bool = False) -> TwinContact:
        """The twin's own contact force, as `SimBus.measure_contact`: the latest published
        step's, or with ``at_last_read`` the one published with the last read's state.
        Raises NotConnectedError, BusError (the shared frame stays locked)."""
        if at_last_read and self._contact_at_read is not None:
            return self._contact_at_read
        frame = self._require_frame("measure contact")
        with self._frame_access("measure contact"):
            values = frame[_CONTACT].copy()
        return _contact_of(values)

    def set_base_motion(self, motion: BaseMotion) -> None:
        """The drone's attitude, acceleration and turning, acting on the arm from now on."""
        self._call("set_base_motion", motion, reply=False)

    def set_plate_pose(
        self,
        index: int,
        point_m: Sequence[float],
        normal: Sequence[float],
        velocity_m_s: Sequence[float] = (0.0, 0.0, 0.0),
        angular_velocity_rad_s: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> None:
        """Move the twin's plate `index` in the simulator process, as
        `SimBus.set_plate_pose`; answered, so its ValueError (naming the index or the
        field) comes back as it is. Raises NotConnectedError, BusError (the process is
        gone or did not answer)."""
        motion = (point_m, normal, velocity_m_s, angular_velocity_rad_s)
        self._call("set_plate_pose", index, *motion)

    def pause(self, paused: bool) -> None:
        """Freeze (True) or resume (False) the simulator, as a starved process freezes: it
        stops stepping and publishing but answers requests; on resume it catches up at most
        `MAX_CATCH_UP_S` of simulated time, as after a stall. For tests and demonstrations of
        stale feedback. Raises NotConnectedError, BusError (the process is gone)."""
        self._call("pause", bool(paused))

    # -- internals -----------------------------------------------------------------------
    def _require_frame(self, instruction: str) -> np.ndarray:
        if self._frame is None:
            raise NotConnectedError(self.ids, instruction, "the simulated bus is not connected")
        return self._frame

    def _frame_access(self, instruction: str) -> _Held:
        return _Held(self._frame_lock, self.ids, instruction)

    def _count(self) -> None:
        self._stats = replace(self._stats, transactions=self._stats.transactions + 1)

    def _call(self, method: str, *args: Any, reply: bool = True) -> Any:
        if self._conn is None:
            raise NotConnectedError(self.ids, method, "the simulated bus is not connected")
        with self._request_lock:
            try:
                self._conn.send((method, args, reply))
                if not reply:
                    return None
                if not self._conn.poll(REPLY_TIMEOUT_S):
                    raise BusError(self.ids, method, "the simulator process did not answer")
                ok, value = self._conn.recv()
            except (OSError, EOFError) as exc:
                raise BusError(self.ids, method, f"the simulator process is gone ({exc})") from exc
        self._count()
        if not ok:
            raise value
        return value


class _Held:
    """The shared frame's lock, bounded: a stuck child is a bus error, never a hang."""

    def __init__(self, lock: Any, ids: tuple[int, ...], instruction: str) -> None:
        self.lock, self.ids, self.instruction = lock, ids, instruction

    def __enter__(self) -> None:
        if not self.lock.acquire(timeout=LOCK_TIMEOUT_S):
            raise BusError(self.ids, self.instruction, "the simulator's shared state is locked")

    def __exit__(self, *exc: object) -> None:
        self.lock.release()


# -- the child process -----------------------------------------------------------------
def _child_main(config: SimBusConfig, conn: Connection, memory_name: str, lock: Any) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C stops the server, which stops us
    memory = SharedMemory(name=memory_name)
    frame = np.ndarray((_FRAME_SIZE,), dtype=np.float64, buffer=memory.buf)
    bus = SimBus(config)
    bus.connect()
    try:
        _publish(bus, frame, lock)
        conn.send("ready")
        _serve(bus, conn, frame, lock)
    finally:
        del frame
        memory.close()


def _serve(bus: SimBus, conn: Connection, frame: np.ndarray, lock: Any) -> None:
    """Step physics against the wall clock; answer requests the moment they arrive."""
    dt = bus.twin.model.opt.timestep
    last, goal_seq, paused = time.monotonic(), 0.0, False
    while True:
        if conn.poll(STEP_S):
            try:
                request = conn.recv()
            except EOFError:
                return  # the parent is gone
            if request is None:
                return
            if request[0] == "pause":
                paused = bool(request[1][0])
                conn.send((True, None))
            else:
                _answer(bus, conn, *request, frame=frame, lock=lock)
        if paused:
            continue
        with lock:
            seq, goal = frame[_GOAL_SEQ], frame[_GOAL][: bus.n].copy()
        if seq != goal_seq:
            goal_seq = seq
            bus.write_goal(goal.tolist())
        now = time.monotonic()
        due = min(now - last, MAX_CATCH_UP_S)  # after a stall, simulated time runs slow
        steps = int(due / dt)
        last = now - (due - steps * dt)
        if steps:
            bus.advance(steps * dt)
            _publish(bus, frame, lock)


def _answer(
    bus: SimBus,
    conn: Connection,
    method: str,
    args: tuple,
    reply: bool,
    *,
    frame: np.ndarray | None = None,
    lock: Any = None,
) -> None:
    try:
        result = (True, getattr(bus, method)(*args))
    except (BusError, ValueError) as exc:
        result = (False, exc)
    if frame is not None:  # a torque change shows in the next read, not a step later
        with lock:
            frame[_TORQUE][: bus.n] = [c.torque_enabled for c in bus.commands]
    if reply:
        conn.send(result)


def _publish(bus: SimBus, frame: np.ndarray, lock: Any) -> None:
    state = bus.read_state()
    codes = [float(servo.hardware_error) for servo in bus.twin.servos]
    platform = bus.twin.platform_m
    contact = _contact_values(bus.twin.contact())
    n = bus.n
    with lock:
        frame[_POS][:n] = state.position_rad
        for name, values in state.readings().items():
            frame[_COLUMN[name]][:n] = values
        frame[_MOVING][:n], frame[_ERR][:n] = state.moving, codes
        frame[_TORQUE][:n] = state.torque_enabled
        frame[_STAMP], frame[_PLATFORM] = state.stamp_s, platform
        frame[_SIM_TIME] = state.sim_time_s
        frame[_CONTACT] = contact

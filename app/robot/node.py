"""The robot node: the control loop, the only owner of the servo bus, behind a link.

It runs the :class:`~app.control.controller.Controller` (read, FK, goal source, gate, IK,
write, safety, publish) on its own bus and takes commands from the station that holds its
link (app/robot/holder.py): operator motion (goal, jog, held jog, move, the wrist), the
runs the station planned and checked (as data: app/link/paths.py), torque, e-stop (from
anyone), reset, gains, joint offsets and the robot model. Each command is an op name and
JSON arguments (app/link/protocol.py); its answer is JSON data or the refusal's error,
with the same kinds the API maps to HTTP codes. What it executes was checked by the
station; the node checks the arguments again and gates every setpoint, as the loop does.

The transport is not here: app/link/zenoh_link.py serves a node over Eclipse Zenoh (the
``deltadash robot`` process), app/link/local.py calls it in one process (the tests).

When the holder's heartbeat stops (``link.station_timeout_s``), the next tick stops the
operator's motion (jog, held jog, go-to) and holds; a run or a hold-in-world too unless
``link.on_station_lost`` is ``continue``. Nothing moves again until a station holds the
link and sends a command.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

import numpy as np

from app.config import Settings
from app.control import commands
from app.control.controller import Controller
from app.control.errors import MotionRefused
from app.control.state import Snapshot
from app.link import robots
from app.link.codec import decode, plain
from app.link.futures import done, then
from app.link.paths import PathSource, SampledPath
from app.link.protocol import PROTOCOL
from app.robot.estop import EstopListener, EstopReceipts
from app.robot.holder import LinkHolder
from app.robot.world import NodeWorld
from app.runs.feasibility import check_path
from hardware.bus import PositionGains

log = logging.getLogger(__name__)
ANYONE = ("estop", "link", "info", "estop_receipt")  # ops that need no link
MAX_MOVE_S = 60.0  # the longest move (the API's bound too)
MAX_START_TOLERANCE_M = 0.01  # a run starts within this of where the robot is commanded
PATH_AGREES_M = 1e-3  # a path's commanded points follow its goals (the lead's shift) to this


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _vector(args: dict[str, Any], name: str, size: int = 3) -> np.ndarray:
    value = args.get(name)
    if not isinstance(value, list) or not all(_is_number(v) for v in value):
        raise ValueError(f"{name}: expected {size} numbers, got {value!r:.80}")
    vector = np.asarray(value, dtype=np.float64)
    if vector.shape != (size,) or not np.isfinite(vector).all():
        raise ValueError(f"{name}: expected {size} finite numbers, got {value!r:.80}")
    return vector


def _optional_vector(args: dict[str, Any], name: str) -> np.ndarray | None:
    return None if args.get(name) is None else _vector(args, name)


def _number(args: dict[str, Any], name: str, default: float | None = None) -> float:
    value = args.get(name, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{name}: expected a finite number, got {value!r:.80}")
    return float(value)


def _optional_number(args: dict[str, Any], name: str) -> float | None:
    return None if args.get(name) is None else _number(args, name)


def _duration(args: dict[str, Any], name: str, most_s: float) -> float | None:
    """An optional duration [s]: None, or a number in (0, most_s]."""
    value = _optional_number(args, name)
    if value is not None and not 0.0 < value <= most_s:
        raise ValueError(f"{name}: must be in (0, {most_s:g}] s, got {value}")
    return value


def _flag(args: dict[str, Any], name: str, default: bool = False) -> bool:
    value = args.get(name, default)
    if not isinstance(value, bool):
        raise ValueError(f"{name}: expected true or false, got {value!r:.80}")
    return value


def _text(args: dict[str, Any], name: str, limit: int = 200) -> str:
    value = args.get(name)
    if not isinstance(value, str) or not 0 < len(value) <= limit:
        raise ValueError(f"{name}: expected a text of 1 to {limit} characters")
    return value


class RobotNode:
    """One robot's loop and its link's authority (``station_timeout_s`` None: its station
    is in the same process and never lost)."""

    def __init__(
        self,
        settings: Settings,
        controller: Controller,
        station_timeout_s: float | None = None,
        name: str = "robot",
    ) -> None:
        self.settings, self.controller, self.name = settings, controller, name
        self.holder = LinkHolder(station_timeout_s)
        self._stop_runs = settings.link.on_station_lost == "stop"
        self._taps = 0
        self._tap_lock = threading.Lock()
        self._tick_listeners: list[Callable[[Snapshot], None]] = []
        self._started_s = time.time()
        # hold-in-world and the drone's pose inputs live beside the loop (app/robot/world.py)
        self.world = NodeWorld(controller)
        # the e-stop's own path into the node (app/robot/estop.py): start_estop_listener
        self.receipts = EstopReceipts(controller)
        self.estop_listener: EstopListener | None = None
        # its ROS 2 side, where a transport gives it one (app/robot/ros.py sets it)
        self.ros: Any = None
        controller.add_listener(self._after_tick)

    # ---- lifecycle ----
    def start(self) -> None:
        self.controller.start()

    def stop(self) -> str | None:
        """Stop the loop (torque off at exit per config) and the pose inputs; why the
        robot could not be left as the config says, else None."""
        try:
            return self.controller.stop()
        finally:
            self.world.close()
            if self.estop_listener is not None:
                self.estop_listener.close()

    def start_estop_listener(self, host: str | None = None) -> EstopListener | None:
        """The node's e-stop listener on ``host`` (default ``server.host``; a node that
        listens beyond loopback gives its link's address, where the pages reach it) and
        ``server.estop_port`` (0: any free port); None (logged) when the config turns it
        off or the port cannot be bound: an e-stop over the link still stops."""
        server = self.settings.server
        if not server.estop_listener:
            return None
        try:
            self.estop_listener = EstopListener(
                self.receipts,
                host or server.host,
                server.estop_port,
                server.http_port,
                server.command_timeout_s,
            )
        except OSError as exc:
            log.warning("e-stop listener not started on port %s: %s", server.estop_port, exc)
        return self.estop_listener

    # ---- the link ----
    def heartbeat(self, station: str, seq: int, mac: str) -> bool:
        """A station's heartbeat (signed: app/robot/holder.py); False when not kept."""
        return self.holder.heartbeat(station, seq, mac)

    def info(self) -> dict[str, Any]:
        """What a station needs to know of this robot: its config (the robot, joints,
        limits, safety, wrist, tool, loop), the model in use, the gains, joint offsets,
        whether gravity is compensated, and the link's holder."""
        controller = self.controller
        view = self.holder.view()
        settings = controller.settings.model_dump(
            mode="json", exclude={"server": {"token"}, "link": {"password"}}
        )
        return {
            "protocol": PROTOCOL,
            "name": self.name,
            "backend": controller.backend,
            "backend_description": controller.backend_description,
            "servo_ids": list(controller.servo_ids),
            "period_s": controller.period_s,
            "settings": settings,
            "model": {
                "robot": robots.robot_data(controller.robot),
                "version": controller.model.version,
                "origin": controller.model.origin,
            },
            "joint_offsets_rad": controller.joint_offsets_rad.tolist(),
            "gravity": controller.gravity is not None,
            "holder": view.holder,
            "started_unix_s": self._started_s,
            "boot": controller.boot,
            "realtime": plain(controller.thread_setup_result),
            "estop_port": None if self.estop_listener is None else self.estop_listener.port,
        }

    def status_view(self) -> dict[str, Any]:
        """The node's own status beside the loop's snapshot, as plain data: its link
        (holder, take-overs, losses), the last press at its e-stop listener, and the drone's
        pose input (``pose``: the tracker's status)."""
        return {
            "link": plain(self.holder.view()),
            "estop": plain(self.receipts.latest()),
            "pose": self.world.service.tracker.status(),
            "ros2": None if self.ros is None else plain(self.ros.view()),
        }

    def authorize(self, station: str, op: str, seq: int, mac: str, body: bytes) -> None:
        """Raise unless command ``op`` may run for ``station``: an op that exists, and
        (but for an e-stop, a take of the link and the node's own information) signed by
        the link's holder (app/robot/holder.py). A transport asks this before it parses
        the command's body: a body from anyone else is never read."""
        if not isinstance(op, str) or not op.isidentifier() or not hasattr(self, f"_op_{op}"):
            raise ValueError(f"op: no command {op!r}")
        if op not in ANYONE:
            self.holder.require(station, op, seq, mac, body)

    def call(
        self,
        station: str,
        op: str,
        args: dict[str, Any] | None = None,
        auth: tuple[int, str, bytes] | None = None,
    ) -> Future:
        """Run command ``op`` with ``args`` for ``station``: a Future of ``(answer, tick)``
        (the answer as plain JSON data; the tick whose snapshot shows it), or of its
        refusal (LinkRefused when ``station`` does not hold the link or did not sign it;
        GoalRejected, MotionRefused, ValueError naming the argument, as the loop
        refuses). ``auth``: the command's ``(seq, mac, body)`` to check (:meth:`authorize`);
        None: the transport checked it already. Raises nothing itself."""
        try:
            if auth is not None:
                self.authorize(station, op, *auth)
            handler = getattr(self, f"_op_{op}", None)
            if handler is None or not op.isidentifier():
                raise ValueError(f"op: no command {op!r}")
            if not isinstance(args, dict | None):
                raise ValueError("args: expected an object")
            outcome = handler(station, args or {})
        except Exception as exc:
            failed: Future = Future()
            failed.set_exception(exc)
            return failed
        answered = outcome if isinstance(outcome, Future) else done(outcome)
        return then(answered, lambda result: (plain(result), self.controller.snapshot().tick))

    def add_tick_listener(self, listener: Callable[[Snapshot], None]) -> None:
        """``listener(snapshot)`` after every tick, in the control thread (keep it fast)."""
        self._tick_listeners.append(listener)

    @property
    def tapped(self) -> bool:
        """A station asked for every tick (a run's log): the transport sends them all."""
        return self._taps > 0

    # ---- the control thread ----
    def _after_tick(self, snap: Snapshot) -> None:
        lost = self.holder.check_lost()
        if lost is not None:
            self._disarm_ros()
            self.controller.submit(self._link_lost)
        for listener in tuple(self._tick_listeners):
            listener(snap)

    def _disarm_ros(self) -> None:
        if self.ros is not None:
            self.ros.armed_by = None

    def _link_lost(self) -> str | None:
        state = self.controller.state
        stopped = commands.link_lost(
            state, "stopped: the station's link was lost (no heartbeat)", self._stop_runs
        )
        if stopped is not None:
            log.warning("station lost: %s stopped, holding", stopped)
        return stopped

    # ---- the ops ----
    def _op_link(self, station: str, args: dict[str, Any]) -> dict[str, Any]:
        protocol = args.get("protocol", PROTOCOL)
        if protocol != PROTOCOL:
            raise ValueError(
                f"protocol: this robot node speaks link protocol {PROTOCOL}, the station "
                f"{protocol!r}: update one of them"
            )
        taken = self.holder.take(station, _flag(args, "take_over"))
        self._disarm_ros()  # every take, even the same station's again: armed anew or not
        page_port = args.get("page_port")  # the station's pages may read the listener's answers
        if self.estop_listener is not None and isinstance(page_port, int) and page_port > 0:
            self.estop_listener.allow_page(page_port)
        # the key goes in this answer, to the station alone; it signs every later command
        return {"took_over_from": taken.took_over_from, "key": taken.key.hex(), **self.info()}

    def _op_release(self, station: str, args: dict[str, Any]) -> bool:
        released = self.holder.release(station)
        if released:
            self._disarm_ros()
        return released

    def _op_info(self, station: str, args: dict[str, Any]) -> dict[str, Any]:
        return self.info()

    def _op_estop_receipt(self, station: str, args: dict[str, Any]) -> Any:
        """The last press that reached the node's own e-stop listener."""
        return self.receipts.latest()

    def _op_tap(self, station: str, args: dict[str, Any]) -> int:
        with self._tap_lock:
            self._taps = max(0, self._taps + (1 if _flag(args, "on") else -1))
            return self._taps

    def _op_estop(self, station: str, args: dict[str, Any]) -> Future:
        return self.controller.estop()

    def _op_reset(self, station: str, args: dict[str, Any]) -> Future:
        return self.controller.reset()

    def _op_torque(self, station: str, args: dict[str, Any]) -> Future:
        return self.controller.set_torque(_flag(args, "enabled"))

    def _model(self, args: dict[str, Any]) -> Any:
        """The model in use, if ``model_version`` (what the station checked against) is
        its version; MotionRefused otherwise."""
        model = self.controller.model
        version = args.get("model_version")
        if version is not None and version != model.version:
            raise MotionRefused(
                f"the robot model changed since this was checked ({model.origin} in use "
                "now): send it again"
            )
        return model

    def _op_goal(self, station: str, args: dict[str, Any]) -> Future:
        self._model(args)
        point = _vector(args, "point_m")
        return self.controller.set_goal(point, _number(args, "phi_rad", 0.0))

    def _op_jog(self, station: str, args: dict[str, Any]) -> Future:
        speed = _optional_number(args, "speed_m_s")
        return self.controller.jog(_vector(args, "delta_m"), speed)

    def _op_hold_jog(self, station: str, args: dict[str, Any]) -> Future:
        return then(self.controller.hold_jog(_vector(args, "velocity_m_s")), plain)

    def _op_move(self, station: str, args: dict[str, Any]) -> Future:
        self._model(args)
        return self.controller.move(
            _optional_vector(args, "point_m"),
            _optional_vector(args, "joints_rad"),
            _duration(args, "duration_s", MAX_MOVE_S),
            _flag(args, "joint_space"),
            _number(args, "phi_rad", 0.0),
        )

    def _op_turn_wrist(self, station: str, args: dict[str, Any]) -> Future:
        return self.controller.turn_wrist(_number(args, "phi_rad"))

    def _op_stop(self, station: str, args: dict[str, Any]) -> Future:
        return self.controller.stop_any()

    def _op_stop_source(self, station: str, args: dict[str, Any]) -> Future:
        source_id = _text(args, "source_id")

        def stop() -> bool:
            source = self.controller.state.source
            if getattr(source, "source_id", None) != source_id:
                return False
            return commands.stop_source(self.controller.state, source)

        return self.controller.submit(stop)

    def _op_run_path(self, station: str, args: dict[str, Any]) -> Future:
        """Play a run the station planned and checked, as samples (app/link/paths.py):
        checked here again before anything moves (its start where the robot is, its
        commanded points its goals shifted by the lead, every sample inside the gate's
        workspace, joint limits, singularity margin and joint speed: app/runs/feasibility.py);
        a refusal names the sample's time and point."""
        model = self._model(args)
        source_id = _text(args, "source_id")
        path = decode(SampledPath, args.get("path") or {})
        if abs(path.period_s - self.controller.period_s) > 1e-12:
            raise ValueError(
                f"path.period_s: {path.period_s} s, the loop's period is "
                f"{self.controller.period_s} s"
            )
        start = _vector(args, "expected_start_m")
        tolerance_m = _number(args, "tolerance_m")
        if not 0.0 <= tolerance_m <= MAX_START_TOLERANCE_M:
            raise ValueError(
                f"tolerance_m: a run starts within {MAX_START_TOLERANCE_M * 1e3:g} mm of the "
                f"robot, got {tolerance_m}"
            )
        check_sampled(model.gate, path, start, self.controller.snapshot().joints_measured_rad)
        source = PathSource(path, source_id)
        play = args.get("play") or {}
        if not isinstance(play, dict):
            raise ValueError("play: expected an object (override, optional_stop)")
        if "override" in play:
            source.playback.steer("feed", override=play["override"])
        if "optional_stop" in play:
            source.playback.steer("optional_stop", on=play["optional_stop"])
        return self.controller.run_source(source, start, tolerance_m, model)

    def _op_steer(self, station: str, args: dict[str, Any]) -> Future:
        """Steer the playing run ``source_id``'s time (app/link/paths.py Playback): pause,
        resume, step, feed (``override`` 0.1 to 1.0), optional_stop (``on``). In the
        control thread, between ticks; the answer is its FeedState. MotionRefused when
        that run no longer plays; ValueError naming the field."""
        source_id = _text(args, "source_id")
        action = _text(args, "action", 20)
        override, on = args.get("override"), args.get("on")

        def steer() -> Any:
            source = self.controller.state.source
            if getattr(source, "source_id", None) != source_id or not isinstance(
                source, PathSource
            ):
                raise MotionRefused("the run is no longer playing: nothing to steer")
            return source.playback.steer(action, override=override, on=on)

        return self.controller.submit(steer)

    def _op_set_gains(self, station: str, args: dict[str, Any]) -> Future:
        given = args.get("gains")
        if not isinstance(given, dict):
            raise ValueError("gains: expected an object of servo id -> gains")
        try:
            gains = {int(sid): PositionGains(**values) for sid, values in given.items()}
        except (TypeError, ValueError) as exc:
            raise ValueError(f"gains: {exc}") from None
        return then(self.controller.set_gains(gains), _gains_out)

    def _op_set_servo_current(self, station: str, args: dict[str, Any]) -> Future:
        """The legs' operating mode and Goal Current [A] (3,) (Controller.set_servo_current);
        ValueError naming the field, TorqueOnError (refused) while torque is on."""
        mode = _text(args, "operating_mode", 40)
        currents = _vector(args, "goal_current_a")
        return then(self.controller.set_servo_current(mode, currents), plain)

    def _op_read_gains(self, station: str, args: dict[str, Any]) -> Future:
        return then(self.controller.read_gains(), _gains_out)

    def _op_joint_offsets(self, station: str, args: dict[str, Any]) -> Future:
        return then(self.controller.set_joint_offsets(_vector(args, "offsets_rad")), plain)

    def _op_use_model(self, station: str, args: dict[str, Any]) -> Future:
        robot = robots.robot_of(args.get("robot"))
        offsets = _vector(args, "offsets_rad")
        origin = _text(args, "origin")
        swapped = self.controller.use_model(robot, offsets, origin)
        return then(swapped, lambda model: {"version": model.version, "origin": model.origin})

    # ---- hold-in-world and the pose inputs (app/robot/world.py) ----
    def _op_pose(self, station: str, args: dict[str, Any]) -> dict[str, Any]:
        return self.world.push(args)

    def _op_pose_status(self, station: str, args: dict[str, Any]) -> dict[str, Any]:
        return self.world.status(args)

    def _op_pose_latest(self, station: str, args: dict[str, Any]) -> dict[str, Any]:
        return self.world.latest(args)

    def _op_ros_goals(self, station: str, args: dict[str, Any]) -> dict[str, Any]:
        """Arm (``enabled`` true) or disarm the ROS goal input for the link's holder."""
        enabled = _flag(args, "enabled")
        if self.ros is None:
            raise ValueError("enabled: this robot node has no ROS 2 side (no Zenoh session)")
        return self.ros.arm_goals(station, enabled)

    def _op_ros_status(self, station: str, args: dict[str, Any]) -> dict[str, Any] | None:
        """The ROS 2 side's status (None: none)."""
        return None if self.ros is None else self.ros.view()

    def _op_restart_inputs(self, station: str, args: dict[str, Any]) -> None:
        self.world.restart(args)

    def _op_touch(self, station: str, args: dict[str, Any]) -> Future:
        """A touch (app/control/touch.py): ``direction`` and optional ``speed_m_s``,
        ``force_n``, ``max_travel_m``, ``retract_m``; errors name the field."""
        names = ("speed_m_s", "force_n", "max_travel_m", "retract_m")
        values = {name: _optional_number(args, name) for name in names}
        given = {name: value for name, value in values.items() if value is not None}
        return self.controller.touch(_vector(args, "direction"), **given)

    def _op_press(self, station: str, args: dict[str, Any]) -> Future:
        """A compliant press (app/control/press.py): ``force_n`` along ``direction`` in
        ``frame`` ("base": from where the tip is; "world": on a hold in the world built
        from ``hold``, as the hold op's arguments), for ``duration_s`` (None: until
        stopped)."""
        frame = _text(args, "frame", 10) if "frame" in args else "base"
        direction = _vector(args, "direction")
        force = _number(args, "force_n")
        duration = _optional_number(args, "duration_s")
        inner = None
        if frame == "world":
            hold = args.get("hold") or {}
            if not isinstance(hold, dict):
                raise ValueError("hold: expected an object (the hold's arguments)")
            self._model(args)
            inner = self.world.hold_source(hold)
        return self.controller.press(direction, force, inner, frame, duration)

    def _op_hold(self, station: str, args: dict[str, Any]) -> Future:
        model = self._model(args)
        source = self.world.hold_source(args)
        source.source_id = _text(args, "source_id")  # type: ignore[attr-defined]
        reply = {
            "goal_world_m": source.goal_world.tolist(),
            "approach_s": source.approach_s,
            "duration_s": source.duration_s,
        }
        # the hold blends in from wherever the robot is: no start point to check
        started = self.controller.run_source(source, np.zeros(3), math.inf, model)
        return then(started, lambda _: reply)


def check_sampled(gate: Any, path: SampledPath, start_m: np.ndarray, near: np.ndarray) -> None:
    """Refuse (GoalRejected, ValueError) a run's samples that do not start at ``start_m``,
    whose commanded points are not their goals shifted by the lead, or that any sample of
    fails the gate's batch check (the station's own, app/runs/feasibility.py)."""
    points = np.asarray(path.points_m, dtype=np.float64)
    if np.linalg.norm(points[0] - start_m) > PATH_AGREES_M:
        raise ValueError("path.points_m: the first sample is not the run's start point")
    times = np.arange(len(points)) * path.period_s
    phi = None if path.phi_rad is None else np.nan_to_num(path.phi_rad)
    near = near if np.isfinite(near).all() else np.zeros(3)
    check_path(gate, times, points, near, phi)
    if path.commanded_m is not None:
        index = np.arange(len(points))
        u = np.clip((times + path.lead_s) / path.period_s, 0, len(points) - 1)
        ahead = np.stack([np.interp(u, index, points[:, a]) for a in range(3)], axis=1)
        off = np.linalg.norm(np.asarray(path.commanded_m) - ahead, axis=1)
        if off.max() > PATH_AGREES_M:
            k = int(np.argmax(off))
            raise ValueError(
                f"path.commanded_m: sample {k} is {off[k] * 1e3:.1f} mm from the goal "
                f"{path.lead_s:g} s ahead (the lead)"
            )
        check_path(gate, times, np.asarray(path.commanded_m), near, phi)


def _gains_out(gains: dict[int, PositionGains]) -> dict[str, dict[str, int]]:
    return {str(sid): dataclasses.asdict(g) for sid, g in gains.items()}

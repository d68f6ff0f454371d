"""The station's handle on a robot node: the loop's interface, over a link.

:class:`RobotClient` answers what the station's code asks of the loop (the
:class:`~app.control.controller.Controller`'s interface: ``snapshot()``, ``set_goal``,
``jog``, ``move``, ``run_source``, ``set_gains``, ...) by sending commands to a robot node
(app/robot/node.py) and reading the state it publishes. The robot's config (robot,
joints, limits, safety, wrist, tool, loop) is the node's: the station adopts it when it
takes the link, and checks goals and plans runs against the same model the node gates
with. Operator leases and procedures (``owner``) stay the station's.

A command's Future is answered once the station's snapshot shows the tick that answered
it (as the controller's are), or with the refusal the node gave (the same exception types:
GoalRejected, MotionRefused, LinkRefused, ...); RobotOffline when the node does not
answer within ``server.command_timeout_s``. ``online`` says whether state still arrives
(within ``link.robot_timeout_s``).
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
import uuid
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from app.config import Settings
from app.control.commands import (
    CommandContext,
    check_goal,
    check_move,
    check_vector,
    ordered_gains,
)
from app.control.errors import MotionRefused
from app.control.model import Robot, RobotModel
from app.control.owner import MotionOwner
from app.control.servo_current import check as check_servo_current
from app.control.state import Snapshot
from app.link import robots
from app.link.codec import plain
from app.link.futures import done, then
from app.link.protocol import PROTOCOL, LinkRefused, RobotOffline, sign
from hardware.bus import PositionGains

log = logging.getLogger(__name__)
Listener = Callable[[Snapshot], None]
# the robot's own sections of the config: the node's, adopted by the station
ROBOT_SECTIONS = (
    "robot",
    "tool",
    "hardware",
    "loop",
    "control",
    "limits",
    "jog",
    "safety",
    "wrist",
)
SHOWN_WITHIN_S = 0.5  # a reply waits this long for the snapshot of its tick
UNSIGNED = ("estop", "link", "info", "estop_receipt")  # ops anyone may send (robot/node.py)


class Transport(Protocol):
    """How a station reaches one robot node (app/robot/local.py in one process,
    app/link/zenoh_station.py over Zenoh)."""

    def call(self, op: str, body: bytes, seq: int, mac: str, timeout_s: float) -> Future:
        """Command ``op`` with its JSON ``body``, signed (``seq``, ``mac``: protocol.py
        ``sign``; 0 and "" for the ops anyone may send): a Future of ``(result, tick)``
        (the tick that answered it), or of the refusal's exception."""
        ...

    def open(
        self,
        station: str,
        on_state: Listener,
        on_ticks: Callable[[list[Snapshot]], None],
        beat: Callable[[], tuple[int, str] | None],
    ) -> None:
        """Speak as ``station``: start delivering the node's states (latest only) and,
        while tapped, every tick in order; send the station's heartbeat (``beat()``: its
        signed sequence number, None before the link is taken)."""
        ...

    def close(self) -> None: ...


class _Gravity:
    """Gravity compensation is on at the node (its model stays there)."""


class RobotClient:
    """One robot node as the station sees it (the Controller's interface)."""

    def __init__(
        self,
        settings: Settings,
        transport: Transport,
        station_id: str | None = None,
        take_over: bool | None = None,
    ) -> None:
        self.station_id = station_id or uuid.uuid4().hex[:12]
        self.settings = settings
        self.transport = transport
        self._take_over = settings.link.take_over if take_over is None else take_over
        self._timeout_s = settings.server.command_timeout_s
        self.owner = MotionOwner()  # procedures hold the robot at the station
        self._listeners: list[Listener] = []
        self._sources: dict[str, Any] = {}  # the station's run sources by id
        self._lock = threading.Lock()
        # answered commands waiting for the snapshot of their tick: (tick, deadline, ...)
        self._pending: list[tuple[int, float, Future, Any]] = []
        self._key = b""  # the link's key (the node's answer to our take): signs our messages
        self._seq = self._beat_seq = 0
        self._boot = ""  # the node's loop we took the link of (RobotInfo.boot)
        self._relinking = False
        self._snapshot = Snapshot()
        self._received_s: float | None = None
        self._offsets = np.zeros(3)
        self._gravity: _Gravity | None = None
        self._info: dict[str, Any] = {}
        self._ctx = CommandContext.from_settings(settings)
        self.servo_ids, self.period_s = self._ctx.servo_ids, self._ctx.period_s
        self.backend, self.backend_description = "robot", "robot node"
        self.bus = None  # the bus is the node's
        self._started = False
        self._opened = False
        self.took_over_from: str | None = None

    # ---- lifecycle ----
    def start(self) -> None:
        """Take the robot node's link, adopt its config and model, and follow its state.
        Raises RobotOffline when it does not answer, LinkRefused when another live station
        holds it (and take-over is off)."""
        if not self._opened:
            self.transport.open(self.station_id, self._on_state, self._on_ticks, self._beat)
            self._opened = True
        result = self._take()
        self.took_over_from = result.get("took_over_from")
        if self.took_over_from:
            log.warning("took the robot's link over from station %s", self.took_over_from)
        self._adopt(result)
        self._started = True

    def reconnect(self) -> None:
        """Take the link again (after the node restarted or the link was lost)."""
        self._adopt(self._take())

    def _take(self) -> dict[str, Any]:
        args = {
            "take_over": self._take_over,
            "protocol": PROTOCOL,
            "page_port": self.settings.server.http_port,  # its pages call the node's e-stop
        }
        body = json.dumps(args).encode()
        sent = self.transport.call("link", body, 0, "", self._timeout_s)
        try:
            result, _ = sent.result(timeout=self._timeout_s + 1.0)
        except TimeoutError:
            raise RobotOffline("the robot node did not answer the link's take") from None
        with self._lock:  # this link's key: every later command and heartbeat is signed
            self._key = bytes.fromhex(str(result.get("key", "")))
            self._seq = self._beat_seq = 0
            self._boot = str(result.get("boot", ""))
        return result

    def _sign(self, op: str, body: bytes) -> tuple[int, str]:
        """The next sequence number and the signature of command ``op`` with ``body``
        (0 and "" for the ops anyone may send)."""
        if op in UNSIGNED:
            return 0, ""
        with self._lock:
            self._seq += 1
            seq, key = self._seq, self._key
        return seq, sign(key, self.station_id, op, seq, body)

    def _beat(self) -> tuple[int, str] | None:
        """The next heartbeat's signed sequence number; None before the link is taken."""
        with self._lock:
            if not self._key:
                return None
            self._beat_seq += 1
            seq, key = self._beat_seq, self._key
        return seq, sign(key, self.station_id, "heartbeat", seq)

    def _adopt(self, info: dict[str, Any]) -> None:
        """The node's config and model become the station's robot."""
        node = info.get("settings") or {}
        update = {name: node[name] for name in ROBOT_SECTIONS if name in node}
        merged = self.settings.model_dump()
        merged.update(update)
        self.settings = type(self.settings).model_validate(merged)
        ctx = CommandContext.from_settings(self.settings)
        model = info.get("model") or {}
        if model.get("version", 0) != 0:
            robot = robots.robot_of(model["robot"])
            gate = replace(ctx.model.gate, robot=robot)
            ctx = replace(ctx, model=RobotModel(gate, model["version"], model["origin"]))
        self._ctx = ctx
        self.servo_ids, self.period_s = ctx.servo_ids, ctx.period_s
        self.backend = str(info.get("backend", "robot"))
        self.backend_description = str(info.get("backend_description", self.backend))
        self._offsets = np.asarray(info.get("joint_offsets_rad", [0.0, 0.0, 0.0]), float)
        self._gravity = _Gravity() if info.get("gravity") else None
        self._info = info

    def halt(self) -> None:
        self._started = False
        self._sources.clear()  # ruckig's plans must not outlive the interpreter's shutdown
        if self._opened:
            self._opened = False
            self.transport.close()

    def stop(self) -> str | None:
        """Give the link up and stop following the node (the node keeps its loop)."""
        if self._started:
            try:
                self._call("release", {}).result(timeout=2.0)
            except Exception as exc:  # gone already: nothing to give up
                log.info("link release: %s", exc)
        self.halt()
        return None

    @property
    def running(self) -> bool:
        return self._started and self.online

    @property
    def online(self) -> bool:
        """The node's loop runs: its state arrived within ``link.robot_timeout_s`` (a
        node in this process: its loop's thread is alive)."""
        local = getattr(self.transport, "node_running", None)
        if local is not None:
            return bool(local)
        received = self._received_s
        return received is not None and (
            time.monotonic() - received <= self.settings.link.robot_timeout_s
        )

    @property
    def offline_for_s(self) -> float | None:
        """How long the node has been silent [s] once it counts as offline; None while
        online or before the link was taken."""
        if not self._started or self.online:
            return None
        received = self._received_s
        return math.inf if received is None else time.monotonic() - received

    def node_status(self) -> dict[str, Any]:
        """The node's own status (its link, its e-stop listener's last press, the drone's
        pose input: app/robot/node.py ``status_view``), as last heard; {} if none yet."""
        status = getattr(self.transport, "node_status", None)
        return (status() if status is not None else None) or {}

    @property
    def info(self) -> dict[str, Any]:
        """What the node said of itself when the link was taken (app/robot/node.py)."""
        return self._info

    # ---- the model, mirrored ----
    @property
    def ctx(self) -> CommandContext:
        return self._ctx

    @property
    def model(self) -> RobotModel:
        return self._ctx.model

    @property
    def robot(self) -> Robot:
        return self._ctx.model.robot

    @property
    def gate(self) -> Any:
        return self._ctx.model.gate

    @property
    def gains(self) -> dict[int, PositionGains]:
        return dict(zip(self.servo_ids, self._snapshot.gains, strict=False))

    @property
    def gravity(self) -> _Gravity | None:
        return self._gravity

    @property
    def joint_offsets_rad(self) -> np.ndarray:
        return self._offsets.copy()

    # ---- state ----
    def snapshot(self) -> Snapshot:
        return self._snapshot

    @property
    def current_source(self) -> Any:
        """The station's object for the node's active source: a run's source, by its id;
        else an object named as the loop's mode (jog, move, ...); None when idle."""
        snap = self._snapshot
        if snap.source_id is not None and snap.source_id in self._sources:
            return self._sources[snap.source_id]
        return _Named(snap.mode) if snap.mode not in ("idle", "estop", "fault") else None

    @property
    def measured_point(self) -> np.ndarray:
        return self._snapshot.point_measured_m

    @property
    def measured_phi(self) -> float:
        return self._snapshot.tool_phi_rad

    @property
    def mode(self) -> str:
        return self._snapshot.mode

    def add_listener(self, listener: Listener) -> None:
        """``listener(snapshot)`` for every tick of the node, in order (the node sends
        them all while someone listens: a run's log)."""
        with self._lock:
            first = not self._listeners
            self._listeners.append(listener)
        if first:
            self._call("tap", {"on": True})

    def remove_listener(self, listener: Listener) -> None:
        with self._lock:
            if listener not in self._listeners:
                return
            self._listeners.remove(listener)
            last = not self._listeners
        if last:
            self._call("tap", {"on": False})

    def _on_state(self, snap: Snapshot) -> None:
        now = time.monotonic()
        with self._lock:
            if self._boot and snap.info.boot != self._boot:
                # another loop than the one whose link we hold: the node was started again
                relink = not self._relinking
                self._relinking = True
            else:
                relink = False
                if snap.tick >= self._snapshot.tick or snap.info.boot != self._snapshot.info.boot:
                    self._snapshot = snap  # never an older one of the same loop
                self._received_s = now
            due, waiting = [], []
            if not relink:
                shown = self._snapshot.tick
                for pending in self._pending:
                    done_now = pending[0] <= shown or pending[1] <= now
                    (due if done_now else waiting).append(pending)
                self._pending = waiting
        if relink:
            threading.Thread(target=self._relink, name="link-relink", daemon=True).start()
            return
        self._mark_finished(snap)
        for _, _, out, result in due:
            out.set_result(result)

    def _relink(self) -> None:
        """The node's loop is a new one (it was started again): take its link again and
        adopt what it says of itself (its model, its e-stop port), until it answers."""
        try:
            deadline = time.monotonic() + max(10.0, self._timeout_s)
            while self._started:
                try:
                    self.reconnect()
                    log.warning("the robot node was started again: its link taken again")
                    return
                except (RobotOffline, LinkRefused) as exc:
                    if time.monotonic() > deadline:
                        log.error("the restarted robot node's link was not taken: %s", exc)
                        return
                    time.sleep(0.2)
        finally:
            with self._lock:
                self._relinking = False

    def _on_ticks(self, snaps: list[Snapshot]) -> None:
        for snap in snaps:
            self._mark_finished(snap)
            for listener in tuple(self._listeners):
                listener(snap)

    def _mark_finished(self, snap: Snapshot) -> None:
        finished = self._sources.get(snap.finished_source_id or "")
        if finished is not None:
            finished.finished = True
        active = self._sources.get(snap.source_id or "")
        if active is not None:
            if snap.source_t_s is not None:
                active.t_s = snap.source_t_s
            active.program_line = snap.source_line
            if snap.source_feed is not None:  # the node's feed override, pause, time left
                active.feed_state = snap.source_feed

    # ---- commands ----
    def _call(self, op: str, args: dict[str, Any]) -> Future:
        """Send ``op``; a Future of its result once the snapshot shows its tick. A command
        refused because this station lost the link (its heartbeat stopped, or the node
        restarted) while no other station took it takes the link again and is sent once
        more: the operator's command is the act that moves the robot again."""
        out: Future = Future()
        body = json.dumps(plain(args), separators=(",", ":")).encode()

        def send(again: bool) -> None:
            seq, mac = self._sign(op, body)
            try:
                sent = self.transport.call(op, body, seq, mac, self._timeout_s)
            except Exception as exc:
                out.set_exception(exc)
                return
            sent.add_done_callback(lambda finished: answered(finished, again))

        def answered(done: Future, again: bool) -> None:
            error = done.exception()
            if isinstance(error, LinkRefused) and error.holder is None and again:
                # not in the transport's thread: taking the link waits for its answer
                threading.Thread(target=retake, name="link-retake", daemon=True).start()
                return
            if error is not None:
                out.set_exception(error)
                return
            result, tick = done.result()
            with self._lock:
                if self._snapshot.tick < tick:  # answered once a snapshot shows its tick
                    self._pending.append((tick, time.monotonic() + SHOWN_WITHIN_S, out, result))
                    return
            out.set_result(result)

        def retake() -> None:
            try:
                self.reconnect()
            except Exception as exc:
                out.set_exception(exc)
                return
            send(False)

        send(op not in ("link", "release"))
        return out

    def request(self, op: str, args: dict[str, Any]) -> Future:
        """Any other op of the node (its pose inputs, ...): a Future of its answer."""
        return self._call(op, args)

    @property
    def command_timeout_s(self) -> float:
        return self._timeout_s

    def _motion(self, op: str, args: dict[str, Any]) -> Future:
        """A command that moves the robot: refused here while a procedure holds it."""
        with self.owner.permit():
            return self._call(op, args)

    def _near_measured(self) -> np.ndarray:
        near = self._snapshot.joints_measured_rad
        return near if np.isfinite(near).all() else np.zeros(3)

    def set_goal(self, point: Any, phi_rad: float = 0.0) -> Future:
        model = self.model
        goal, phi = check_goal(model.gate, point, phi_rad, self._near_measured())
        args = {"point_m": goal, "phi_rad": phi, "model_version": model.version}
        return self._motion("goal", args)

    def jog(self, delta_m: Any, speed_m_s: float | None = None) -> Future:
        delta = check_vector(delta_m, "delta_m")
        return self._motion("jog", {"delta_m": delta, "speed_m_s": speed_m_s})

    def hold_jog(self, velocity_m_s: Any) -> Future:
        velocity = check_vector(velocity_m_s, "velocity_m_s")
        return self._motion("hold_jog", {"velocity_m_s": velocity})

    def move(
        self,
        point: Any = None,
        joints: Any = None,
        duration_s: float | None = None,
        joint_space: bool = False,
        phi_rad: float = 0.0,
    ) -> Future:
        model = self.model
        target, joint_space = check_move(
            model.gate, point, joints, joint_space, self._near_measured(), phi_rad
        )
        args: dict[str, Any] = {
            "duration_s": duration_s,
            "joint_space": joint_space,
            "phi_rad": float(phi_rad),
            "model_version": model.version,
        }
        args["joints_rad" if point is None else "point_m"] = target
        return self._motion("move", args)

    def touch(self, direction: Any, **values: Any) -> Future:
        """Start a touch on the node (app/control/contact_commands.py ``touch``):
        ``direction`` (3,) and the optional ``speed_m_s``, ``force_n``, ``max_travel_m``,
        ``retract_m`` (None: the node's [contact] defaults)."""
        args = {"direction": check_vector(direction, "direction"), **values}
        return self._motion("touch", args)

    def press(
        self,
        direction: Any,
        force_n: float,
        frame: str = "base",
        duration_s: float | None = None,
        hold: dict[str, Any] | None = None,
    ) -> Future:
        """Start a compliant press on the node (app/control/press.py): ``force_n`` [N]
        along ``direction`` (3,) in ``frame``; "world" presses on a hold in the world built
        from ``hold`` (the hold op's arguments)."""
        args: dict[str, Any] = {
            "direction": check_vector(direction, "direction"),
            "force_n": force_n,
            "frame": frame,
            "duration_s": duration_s,
            "model_version": self.model.version,
        }
        if hold is not None:
            args["hold"] = hold
        return self._motion("press", args)

    def run_source(
        self,
        source: Any,
        expected_start_m: np.ndarray,
        tolerance_m: float = 2e-3,
        model: RobotModel | None = None,
    ) -> Future:
        """Send a planned source to the node to play from ``expected_start_m`` [m]: a run
        as data (``source.sampled(period_s)``: a path, a program), or a source the node
        builds itself (``source.remote_op`` with ``source.remote_args()``: a hold-in-world).
        A Future of the node's answer; MotionRefused for a source that is neither."""
        sampled = getattr(source, "sampled", None)
        remote_op = getattr(source, "remote_op", None)
        if sampled is None and remote_op is None:
            raise MotionRefused(f"a {getattr(source, 'name', 'source')} cannot run on a robot node")
        source_id = getattr(source, "source_id", None) or uuid.uuid4().hex[:12]
        source.source_id = source_id
        self._sources[source_id] = source
        if len(self._sources) > 32:  # keep the last ones: a late tick may name them
            self._sources.pop(next(iter(self._sources)))
        used = model or self.model
        if remote_op is not None:
            args = {**source.remote_args(), "source_id": source_id, "model_version": used.version}
            return self._motion(remote_op, args)
        tolerance = None if not np.isfinite(tolerance_m) else float(tolerance_m)
        args = {
            "source_id": source_id,
            "path": sampled(self.period_s),
            "expected_start_m": np.asarray(expected_start_m, float),
            "tolerance_m": tolerance,
            "model_version": used.version,
            # the feed override and optional stop it starts with (its page's settings)
            "play": dict(getattr(source, "start_play", None) or {}),
        }
        return self._motion("run_path", args)

    def steer_source(self, source: Any, action: str, **values: Any) -> Future:
        """Steer a playing run's time (app/link/paths.py ``Playback.steer``: pause, resume,
        step, feed with ``override``, optional_stop with ``on``): a Future of the node's
        FeedState as plain data; MotionRefused when that run no longer plays."""
        source_id = getattr(source, "source_id", None)
        if source_id is None:
            raise MotionRefused("the run is not playing on the robot")
        args = {"source_id": source_id, "action": action, **values}
        if action in ("resume", "step"):  # these move the robot: not while a procedure holds it
            return self._motion("steer", args)
        return self._call("steer", args)

    def stop_source(self, source: Any) -> Future:
        source_id = getattr(source, "source_id", None)
        if source_id is None:
            return done(False)
        return self._call("stop_source", {"source_id": source_id})

    def stop_any(self) -> Future:
        return self._call("stop", {})

    def set_torque(self, enabled: bool) -> Future:
        return self._call("torque", {"enabled": bool(enabled)})

    def estop(self) -> Future:
        return self._call("estop", {})

    def reset(self) -> Future:
        return self._call("reset", {})

    def turn_wrist(self, phi_rad: Any) -> Future:
        phi = self.gate.check_phi(phi_rad)
        return self._motion("turn_wrist", {"phi_rad": phi})

    def set_gains(self, gains: dict[int, PositionGains]) -> Future:
        wrist = self.settings.wrist.servo_id if self.settings.wrist.enabled else None
        legs = {sid: g for sid, g in gains.items() if sid != wrist}  # the wrist's: the node's
        ordered_gains(legs, tuple(self.servo_ids))  # refused here naming the ids
        wire = {str(sid): g for sid, g in gains.items()}
        return then(self._motion("set_gains", {"gains": wire}), _gains_in)

    def set_servo_current(self, mode: str, currents_a: Any) -> Future:
        """The legs' operating mode and Goal Current [A] (3,) on the node (torque off):
        checked here first (ValueError naming the field), then as the node's
        Controller.set_servo_current; a Future of {"operating_mode", "goal_current_a"}."""
        currents = check_servo_current(mode, currents_a)
        args = {"operating_mode": mode, "goal_current_a": list(currents)}
        return self._motion("set_servo_current", args)

    def read_gains(self) -> Future:
        return then(self._call("read_gains", {}), _gains_in)

    def set_joint_offsets(self, offsets_rad: Any) -> Future:
        offsets = np.asarray(offsets_rad, dtype=float)

        def applied(result: Any) -> Any:
            self._offsets = offsets.copy()
            return result

        return then(self._motion("joint_offsets", {"offsets_rad": offsets}), applied)

    def use_model(self, robot: Robot, offsets_rad: Any, origin: str) -> Future:
        current = self.model
        new = current.replaced(robot, origin)  # the gate built here, as the node builds its own
        offsets = np.asarray(offsets_rad, dtype=float)

        def swapped(result: Any) -> RobotModel:
            model = RobotModel(new.gate, int(result["version"]), str(result["origin"]))
            self._ctx = replace(self._ctx, model=model)
            self._offsets = offsets.copy()
            return model

        args = {"robot": robots.robot_data(robot), "offsets_rad": offsets, "origin": origin}
        return then(self._motion("use_model", args), swapped)


class _Named:
    """A stand-in for a source the station did not make (a jog, a move): its name."""

    def __init__(self, name: str) -> None:
        self.name = name


def _gains_in(wire: dict[str, dict[str, int]]) -> dict[int, PositionGains]:
    return {int(sid): PositionGains(**values) for sid, values in wire.items()}

"""The station's Foxglove live server: the robot for the Foxglove app, while it runs.

A thread follows the station's view of the loop as the 3D scene and the telemetry
WebSocket do: it reads the latest snapshot (``controller.snapshot()``) at
``foxglove.rate_hz`` and sends each new tick once, on foxglove-sdk's WebSocket server
(protocol ``foxglove.sdk.v1``). The periodic channels are built only while a client
subscribes to them. Faults, e-stop, warnings and the link's state become Log messages as
they change; each run's start and end become an Event (and a Log line), from the run
manager's records. Channels and encodings: messages.py and docs/foxglove.md.

Binding: ``foxglove.host`` (unset: ``server.host``). With ``server.token`` set, clients
need it (front.py); beyond loopback a token must be set, as for the API.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import foxglove
from foxglove.channels import EventChannel, FrameTransformsChannel, JointStatesChannel, LogChannel
from foxglove.messages import LogLevel

from app.config import ConfigError, Settings
from app.control.authority import is_loopback
from app.foxglove import messages
from app.foxglove.front import TokenFront

log = logging.getLogger(__name__)
NAME = "deltadash"
RECENT_RUNS = 8  # a new run is among the latest listed: only these are looked at
RUNS_EVERY_S = 0.1  # how often the run manager's records are looked at (sorting them costs)


def bind_host(settings: Settings) -> str:
    """Where the Foxglove server listens: ``foxglove.host``, else ``server.host``.
    Raises ConfigError beyond loopback without ``server.token`` (the API's own rule:
    Foxglove's protocol has no login, so the token is the only door)."""
    host = settings.foxglove.host or settings.server.host
    if not is_loopback(host) and settings.server.token is None:
        raise ConfigError(
            f"foxglove.host = {host!r} is reachable from other machines: set server.token "
            "(--token or DELTADASH_TOKEN); Foxglove clients then send it as ?token="
        )
    return host


class RunWatch:
    """The runs that started or ended since the last look, from the run manager's
    records (runs saved before the server started are not news)."""

    def __init__(self, runs: Callable[[], Any]) -> None:
        self._runs = runs
        self._seen: set[str] | None = None  # the runs listed at the first look: old news
        self._running: dict[str, Any] = {}
        self.changes()

    def changes(self) -> list[tuple[Any, bool]]:
        """(run, ended) in the order they happened: a run seen for the first time is a
        start (and also an end if it is already over)."""
        manager = self._runs()
        if manager is None:
            return []
        if self._seen is None:
            self._seen = {run.run_id for run in manager.list()}
            return []
        out: list[tuple[Any, bool]] = []
        for run_id, run in list(self._running.items()):
            if run.state != "running":
                del self._running[run_id]
                out.append((run, True))
        try:
            recent = manager.list()[:RECENT_RUNS]
        except RuntimeError:  # a run added while its dict was read (another thread): next look
            recent = []
        for run in reversed(recent):
            if run.run_id in self._seen:
                continue
            self._seen.add(run.run_id)
            out.append((run, False))
            if run.state == "running":
                self._running[run.run_id] = run
            else:
                out.append((run, True))
        return out


class FoxgloveLive:
    """The live server for one station: ``start()``, ``stop()``; ``port`` once started."""

    def __init__(self, settings: Settings, controller: Any, runs: Callable[[], Any]) -> None:
        self.settings, self.controller = settings, controller
        self.host = bind_host(settings)
        self.period_s = 1.0 / settings.foxglove.rate_hz
        self.builder = messages.Builder(settings)
        self.context = foxglove.Context()  # its own channels: one app's never meet another's
        ctx = self.context
        self.tf = FrameTransformsChannel(messages.TF, context=ctx)
        self.joints = JointStatesChannel(messages.JOINT_STATES, context=ctx)
        self.tracking = foxglove.Channel(
            messages.TRACKING, schema=messages.TRACKING_SCHEMA, context=ctx
        )
        self.loop = foxglove.Channel(messages.LOOP, schema=messages.LOOP_SCHEMA, context=ctx)
        self.log = LogChannel(messages.LOG, context=ctx)
        self.runs = EventChannel(messages.RUNS, context=ctx)
        self._run_watch = RunWatch(runs)
        self._runs_due = 0.0
        self._state_log = messages.StateLog()
        self._online = True
        self._last_tick: tuple[str, int] | None = None
        self.server: Any = None
        self.front: TokenFront | None = None
        self.published = 0  # ticks sent
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        """The port clients connect to (the token front's where there is one)."""
        if self.front is not None:
            return self.front.port
        return int(self.server.port) if self.server is not None else 0

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host  # an IPv6 address
        return f"ws://{host}:{self.port}"

    def start(self) -> None:
        """Listen and start following the robot. Raises RuntimeError naming the address
        when it cannot be had (the port taken)."""
        token = self.settings.server.token
        wanted = self.settings.foxglove.port
        where = f"the Foxglove live server on {self.host}:{wanted}"
        try:
            if token is None:
                self.server = foxglove.start_server(
                    name=NAME, host=self.host, port=wanted, context=self.context
                )
            else:  # the SDK's server on loopback only, the token's door where clients come
                self.server = foxglove.start_server(
                    name=NAME, host="127.0.0.1", port=0, context=self.context
                )
                self.front = TokenFront(self.host, wanted, int(self.server.port), token)
                self.front.start()
        except (OSError, RuntimeError) as exc:
            if self.server is not None:
                self.server.stop()
            raise RuntimeError(f"{where}: {exc}") from exc
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="foxglove-live", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self.front is not None:
            self.front.stop()
        if self.server is not None:
            self.server.stop()
        for channel in (self.tf, self.joints, self.tracking, self.loop, self.log, self.runs):
            channel.close()

    def _run(self) -> None:
        due = time.monotonic()
        failures = 0
        while not self._stop.wait(max(0.0, due - time.monotonic())):
            due += self.period_s
            now = time.monotonic()
            if due < now:  # behind (a busy machine): the next slot from now, no burst
                due = now + self.period_s
            try:
                self.publish(time.time_ns())
                failures = 0
            except Exception:  # a bug here must not end the thread, nor flood the log
                failures += 1
                if failures in (1, 10, 100) or failures % 1000 == 0:
                    log.exception("Foxglove: publishing failed (%d times in a row)", failures)

    def publish(self, stamp_ns: int) -> None:
        """One look at the robot: its new tick on the periodic channels, and what changed
        (faults, e-stop, the link, runs) on the log and the events."""
        snap = self.controller.snapshot()
        lines: list[tuple[LogLevel, str]] = []
        online = bool(getattr(self.controller, "online", True))
        if online != self._online:
            self._online = online
            if online:
                lines.append((LogLevel.Info, "robot online again"))
            else:
                silent = getattr(self.controller, "offline_for_s", None)
                lines.append((LogLevel.Error, f"robot offline (silent for {silent or 0:.1f} s)"))
        key = (snap.info.boot, snap.tick)
        if key != self._last_tick:
            self._last_tick = key
            self._periodic(snap, stamp_ns)
            lines += self._state_log.changes(snap)
        for level, text in lines:
            self.log.log(messages.log(stamp_ns, level, text), log_time=stamp_ns)
        now = time.monotonic()
        if now < self._runs_due:
            return
        self._runs_due = now + RUNS_EVERY_S
        for run, ended in self._run_watch.changes():
            self.runs.log(messages.run_event(run, ended, stamp_ns), log_time=stamp_ns)
            level, text = messages.run_text(run, ended)
            self.log.log(messages.log(stamp_ns, level, text), log_time=stamp_ns)

    def _periodic(self, snap: Any, stamp_ns: int) -> None:
        """The tick on every channel a client follows, all with the same log time."""
        if self.tf.has_sinks():
            self.tf.log(self.builder.transforms(snap, stamp_ns), log_time=stamp_ns)
        if self.joints.has_sinks():
            self.joints.log(self.builder.joint_states(snap, stamp_ns), log_time=stamp_ns)
        for channel, build in (
            (self.tracking, messages.tracking),
            (self.loop, messages.loop_health),
        ):
            if channel.has_sinks():  # strict JSON: a NaN that slipped through is a bug
                body = json.dumps(build(snap), allow_nan=False).encode()
                channel.log(body, log_time=stamp_ns)
        self.published += 1


def start_foxglove(settings: Settings, controller: Any, runs: Callable[[], Any]) -> Any:
    """The lifespan's hook: a started FoxgloveLive per ``settings.foxglove``, or None when
    it is off. Raises ConfigError (beyond loopback without a token), or RuntimeError (its
    port taken): an operator who asked for it learns at once that it is not
    there, rather than finding the station on another port."""
    if not settings.foxglove.enabled:
        return None
    live = FoxgloveLive(settings, controller, runs)
    live.start()
    print(f"deltadash: Foxglove live server on {live.url}", flush=True)
    return live

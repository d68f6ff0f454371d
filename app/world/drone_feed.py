"""The simulated drone as a pose input: its measured poses streamed into the pose tracker.

``POST /api/mav/simulated`` starts one (a drift profile as the thesis's test 6.2: drift,
tilt, yaw, gusts, rate, latency, seed) so the page can choose the simulated drone as its
pose source, watch it live (``GET /api/mav/pose``: source "simulated", rate, age, pose)
and hold in the world on it from start to finish on the twin, exactly as on a motion
capture stream: the hold follows the pose input (source "external"), goes stale when the
feed stops and faults when it is lost.

The drone's time is the station's ``time.monotonic()``: a feed started again continues
the same clock, so the tracker never sees its time go back.
"""

from __future__ import annotations

import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import asdict
from typing import Any

import numpy as np

from app.world.drone_sim import DroneSimParams, SimulatedDrone

MAX_FAILURES = 50  # pushes failing in a row (the node gone): the feed stops itself


def pose_message(drone: SimulatedDrone, t_s: float) -> tuple[float, dict[str, Any]]:
    """(stamp [s], the pose JSON of the drone's newest measurement at ``t_s`` [s]) with
    ``"source": "simulated"``: position [m], quaternion (w, x, y, z), velocity [m/s]."""
    stamp, pose, velocity = drone.measured(t_s)
    message = {
        "t": stamp,
        "position": np.asarray(pose.position, dtype=float).tolist(),
        "quaternion": np.asarray(pose.quaternion, dtype=float).tolist(),
        "velocity": np.asarray(velocity, dtype=float).tolist(),
        "source": "simulated",
    }
    return stamp, message


class DroneFeed:
    """A thread pushing a SimulatedDrone's measurements into the pose input ``push`` (a
    callable taking the pose JSON: WorldClient.push) at its rate, until ``stop``, or until
    ``allowed`` (checked before each push; None: always) says False: the feed stops itself
    then, saying so in ``last_error`` (the lease that started it given back or taken)."""

    def __init__(
        self,
        push: Callable[[dict[str, Any]], Any],
        params: DroneSimParams,
        clock: Callable[[], float] = time.monotonic,
        allowed: Callable[[], bool] | None = None,
    ) -> None:
        self.push, self.params, self.clock, self.allowed = push, params, clock, allowed
        self.drone = SimulatedDrone(params)
        self.sent = 0
        self.failures = 0
        self.last_error: str | None = None
        self._last_stamp: float | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="drone-feed", daemon=True)

    def start(self) -> DroneFeed:
        self._thread.start()
        return self

    @property
    def running(self) -> bool:
        return self._thread.is_alive() and not self._stop.is_set()

    def step(self, t_s: float) -> bool:
        """Push the newest measurement at ``t_s`` [s] unless it was pushed already: True
        when one was pushed. A failing push is counted (``failures``, ``last_error``)."""
        stamp, message = pose_message(self.drone, t_s)
        if self._last_stamp is not None and stamp <= self._last_stamp:
            return False
        self._last_stamp = stamp
        try:
            self.push(message)
        except Exception as exc:  # the node busy or gone: counted, said, tried again
            self.failures += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
            return False
        self.failures = 0
        self.sent += 1
        return True

    def _run(self) -> None:
        period = 1.0 / self.params.rate_hz
        while not self._stop.wait(period / 2):  # twice per measurement: none skipped
            if self.allowed is not None and not self.allowed():
                self.last_error = "stopped: the lease that started it was given back or taken"
                self._stop.set()
                return
            self.step(self.clock())
            if self.failures >= MAX_FAILURES:
                self.last_error = f"stopped: {self.last_error}"
                return

    def stop(self) -> None:
        """Stop the feed (the pose input then goes stale, then lost); waits for the thread."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)

    def status(self) -> dict[str, Any]:
        """``running``, the drone's ``params`` (SI: m, deg, Hz, s), poses ``sent`` and the
        ``last_error``."""
        return {
            "running": self.running,
            "params": asdict(self.params),
            "sent": self.sent,
            "last_error": self.last_error,
        }


# one feed per pose input (the station's WorldClient), without a field on it
_feeds: weakref.WeakKeyDictionary[Any, DroneFeed] = weakref.WeakKeyDictionary()
_lock = threading.Lock()


def feed_of(world: Any) -> DroneFeed | None:
    """The simulated drone feeding ``world``'s pose input (running or last stopped)."""
    with _lock:
        return _feeds.get(world)


def start_feed(
    world: Any, params: DroneSimParams, allowed: Callable[[], bool] | None = None
) -> DroneFeed:
    """Stop ``world``'s feed if any and start one of ``params`` pushing into
    ``world.push`` while ``allowed()`` (None: until stopped); returns it."""
    stop_feed(world)
    feed = DroneFeed(world.push, params, allowed=allowed).start()
    with _lock:
        _feeds[world] = feed
    return feed


def stop_feed(world: Any) -> DroneFeed | None:
    """Stop ``world``'s feed (kept for its status); None when it had none."""
    feed = feed_of(world)
    if feed is not None:
        feed.stop()
    return feed

"""Which station holds a robot node's link: one at a time, take-over explicit and logged.

A station takes the link (``take``) before it commands anything but an e-stop; its
heartbeat keeps it. A station whose heartbeat stopped for ``timeout_s`` has lost the link:
the node stops the operator's motion (app/robot/node.py), and the next station takes the
link without a take-over. While the holder is alive, another station gets it only with
``take_over`` (the node logs whose it was). Times are the node's monotonic clock [s].

Safe from any thread (Zenoh's callback threads and the control thread ask it).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from app.link.protocol import LinkRefused

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class HolderView:
    """The link as the node sees it: the holding station's id (None: nobody), how long
    since its last heartbeat [s] (None: nobody holds it), whether it is lost (its heartbeat
    stopped), and how many times the link was taken over or lost since start."""

    holder: str | None
    heartbeat_age_s: float | None
    lost: bool
    takeovers: int
    losses: int


class LinkHolder:
    """The link's holder and its heartbeat (``timeout_s`` None: the link is never lost:
    a station in the node's own process)."""

    def __init__(
        self, timeout_s: float | None, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.timeout_s, self._clock = timeout_s, clock
        self._lock = threading.Lock()
        self._holder: str | None = None
        self._seen: dict[str, float] = {}
        self._lost = False
        self.takeovers = 0
        self.losses = 0

    def heartbeat(self, station: str) -> None:
        """``station`` is alive now."""
        with self._lock:
            self._seen[station] = self._clock()
            if len(self._seen) > 64:  # forget the stations long gone
                oldest = min(self._seen, key=self._seen.__getitem__)
                self._seen.pop(oldest)

    def _alive(self, station: str, now: float) -> bool:
        if self.timeout_s is None:
            return True
        seen = self._seen.get(station)
        return seen is not None and now - seen <= self.timeout_s

    def take(self, station: str, take_over: bool = False) -> str | None:
        """Give the link to ``station``; returns the station it was taken from when that
        one was alive (a take-over), else None. Raises LinkRefused while another station
        holds it and is alive, unless ``take_over``."""
        with self._lock:
            now = self._clock()
            self._seen[station] = now  # the take is a heartbeat
            holder = self._holder
            if holder is None or holder == station or not self._alive(holder, now):
                self._holder, self._lost = station, False
                return None
            if not take_over:
                raise LinkRefused(
                    f"station {holder} holds this robot's link; take it over explicitly "
                    "(take_over) to command the robot from here",
                    holder,
                )
            self._holder, self._lost = station, False
            self.takeovers += 1
        log.warning("station %s took the robot's link over from station %s", station, holder)
        return holder

    def release(self, station: str) -> bool:
        """``station`` gives the link up; False if it did not hold it."""
        with self._lock:
            if self._holder != station:
                return False
            self._holder = None
            return True

    def require(self, station: str) -> None:
        """Raise LinkRefused unless ``station`` holds the link (and is alive)."""
        with self._lock:
            if self._holder == station and self._alive(station, self._clock()):
                self._seen[station] = self._clock()  # a command is a heartbeat
                return
            holder = self._holder
        if holder is None or holder != station:
            raise LinkRefused(
                "this station does not hold the robot's link: take it first"
                + (f" (station {holder} holds it)" if holder else ""),
                holder,
            )
        raise LinkRefused("this station's heartbeat stopped: take the robot's link again")

    def check_lost(self) -> str | None:
        """The holder whose heartbeat just stopped (once per loss), else None. The node
        asks each tick; the lost holder keeps no authority (it must take the link again)."""
        with self._lock:
            holder = self._holder
            if holder is None or self._lost or self._alive(holder, self._clock()):
                return None
            self._lost = True
            self._holder = None
            self.losses += 1
        log.warning("station %s lost the robot's link: its heartbeat stopped", holder)
        return holder

    def view(self) -> HolderView:
        with self._lock:
            holder, now = self._holder, self._clock()
            seen = self._seen.get(holder) if holder is not None else None
            age = None if seen is None else now - seen
            return HolderView(holder, age, self._lost, self.takeovers, self.losses)

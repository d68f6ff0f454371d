"""Which station holds a robot node's link: one at a time, take-over explicit and logged.

A station takes the link (``take``) before it commands anything but an e-stop; its
heartbeat keeps it. A station whose heartbeat stopped for ``timeout_s`` has lost the link:
the node stops the operator's motion (app/robot/node.py), and the next station takes the
link without a take-over. While the holder is alive, another station gets it only with
``take_over`` (the node logs whose it was). Times are the node's monotonic clock [s].

Each take hands the holder a fresh secret key (``Taken.key``, in the answer to the
station alone). Its commands and heartbeats are signed with it (app/link/protocol.py
``sign``) and carry a growing sequence number: a peer that reads the holder's id (the
node's published status), a heartbeat or a command can neither command as the holder,
nor keep a dead holder alive, nor replay what it saw.

Safe from any thread (Zenoh's callback threads and the control thread ask it).
"""

from __future__ import annotations

import logging
import math
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from app.link.protocol import LinkRefused, signed

log = logging.getLogger(__name__)
REPLAY_WINDOW = 1024  # a command's sequence number may come this far behind the highest


@dataclass(frozen=True)
class HolderView:
    """The link as the node sees it: the holding station's id (None: nobody), how long
    since its last heartbeat [s] (None: nobody holds it), whether it is lost (its heartbeat
    stopped), how many times the link was taken over or lost since start, and the longest
    a holder was silent (between two of its signed messages) since start [s]."""

    holder: str | None
    heartbeat_age_s: float | None
    lost: bool
    takeovers: int
    losses: int
    worst_gap_s: float = 0.0  # the longest silence of a holder (its heartbeats) since start


@dataclass(frozen=True)
class Taken:
    """A take's outcome: the station it was taken from (a take-over; None: nobody alive
    held it) and the new holder's secret key."""

    took_over_from: str | None
    key: bytes


class LinkHolder:
    """The link's holder and its heartbeat (``timeout_s`` None: the link is never lost:
    a station in the node's own process)."""

    def __init__(
        self, timeout_s: float | None, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.timeout_s, self._clock = timeout_s, clock
        self._lock = threading.Lock()
        self._holder: str | None = None
        self._key = b""
        self._beat_seq = 0  # the holder's last heartbeat's sequence number
        self._high = 0  # the highest command sequence number seen, and those of the window
        self._seen: set[int] = set()  # below it that were seen (commands cross out of order)
        self._beat_at: float | None = None  # the holder's last signed heartbeat or command
        self._lost = False
        self.takeovers = 0
        self.losses = 0
        self.worst_gap_s = 0.0

    def heartbeat(self, station: str, seq: int, mac: str) -> bool:
        """A heartbeat from ``station``: kept when it is the holder's, signed with its key,
        and newer than any message of its so far; False (ignored) otherwise."""
        with self._lock:
            if station != self._holder or seq <= self._beat_seq or self._beat_at == -math.inf:
                return False
            if not signed(self._key, station, "heartbeat", seq, b"", mac):
                return False
            self._beat_seq = seq
            self._beaten(self._clock())
            return True

    def _beaten(self, now: float) -> None:
        if self._beat_at is not None:
            self.worst_gap_s = max(self.worst_gap_s, now - self._beat_at)
        self._beat_at = now

    def _fresh(self, seq: int) -> bool:
        """A command's sequence number not seen before: above the window's floor and not
        one of those seen (commands in flight together may arrive in any order)."""
        if seq <= self._high - REPLAY_WINDOW or seq in self._seen or seq <= 0:
            return False
        self._seen.add(seq)
        self._high = max(self._high, seq)
        floor = self._high - REPLAY_WINDOW
        if len(self._seen) > 2 * REPLAY_WINDOW:
            self._seen = {s for s in self._seen if s > floor}
        return True

    def _alive(self, now: float) -> bool:
        """The holder's heartbeat is fresh (always, for a station in the node's process)."""
        if self._beat_at == -math.inf:  # expired: known to be gone
            return False
        if self.timeout_s is None:
            return True
        return self._beat_at is not None and now - self._beat_at <= self.timeout_s

    def take(self, station: str, take_over: bool = False) -> Taken:
        """Give the link to ``station`` with a fresh key. Raises LinkRefused while another
        station holds it and is alive, unless ``take_over``."""
        with self._lock:
            now = self._clock()
            holder = self._holder
            took = None
            if holder is not None and holder != station and self._alive(now):
                if not take_over:
                    raise LinkRefused(
                        f"station {holder} holds this robot's link: to command the robot "
                        "from here, take it over explicitly (deltadash serve --take-over, "
                        "or [link] take_over = true)",
                        holder,
                    )
                took = holder
                self.takeovers += 1
            self._holder, self._lost = station, False
            self._key, self._beat_at = secrets.token_bytes(32), now
            self._beat_seq, self._high, self._seen = 0, 0, set()
            key = self._key
        if took is not None:
            log.warning("station %s took the robot's link over from station %s", station, took)
        return Taken(took, key)

    def release(self, station: str) -> bool:
        """``station`` gives the link up (its signed ``release``, already required);
        False if it did not hold it."""
        with self._lock:
            if self._holder != station:
                return False
            self._holder, self._key = None, b""
            return True

    def require(self, station: str, op: str, seq: int, mac: str, body: bytes) -> None:
        """Raise LinkRefused unless ``station`` holds the link, is alive, and signed this
        message (``op``, ``seq``, ``body``) with its key, with a sequence number it has not
        used; the message then counts as a heartbeat."""
        with self._lock:
            holder, now = self._holder, self._clock()
            if holder is not None and holder == station:
                if not self._alive(now):
                    raise LinkRefused(
                        "this station's heartbeat stopped: take the robot's link again", None
                    )
                if signed(self._key, station, op, seq, body, mac) and self._fresh(seq):
                    self._beaten(now)
                    return
                raise LinkRefused(
                    f"the command is not signed with this link's key ({op}, seq {seq}): "
                    "take the robot's link again",
                    None,
                )
        raise LinkRefused(
            "this station does not hold the robot's link: take it first"
            + (f" (station {holder} holds it)" if holder else ""),
            holder,
        )

    def expire(self) -> None:
        """The holder is known to be gone (an embedded node's station died): its link is
        lost as of now, whatever its last heartbeat said."""
        with self._lock:
            if self._holder is not None:
                self._beat_at = -math.inf

    def check_lost(self) -> str | None:
        """The holder whose heartbeat just stopped (once per loss), else None. The node
        asks each tick; the lost holder keeps no authority (it must take the link again)."""
        with self._lock:
            holder = self._holder
            if holder is None or self._lost or self._alive(self._clock()):
                return None
            self._lost = True
            self._holder, self._key = None, b""
            self.losses += 1
        log.warning("station %s lost the robot's link: its heartbeat stopped", holder)
        return holder

    def view(self) -> HolderView:
        with self._lock:
            holder, now, seen = self._holder, self._clock(), self._beat_at
            age = None if holder is None or seen is None else now - seen
            return HolderView(
                holder, age, self._lost, self.takeovers, self.losses, self.worst_gap_s
            )

"""Who may move the robot: the token and the control lease, one check for every path.

Every command that can move the robot or change its power (goal, jog, move, torque, reset,
runs, hold) passes ``Authority.check`` with the caller's lease id, whether it came over HTTP
(app/server/api/deps.py) or from the 3D scene (app/scene/access.py). E-stop is the one
exception: anyone may stop the robot.

The lease is a secret. ``take`` hands out a fresh lease id (``secrets.token_urlsafe``) that
only its holder learns; the public ``view`` says whether control is held, since when and the
holder's display name, never the id. A lease lapses after ``timeout_s`` without a command:
a lapsed lease may be taken by anyone without ``take_over``, but until someone does, its
holder's id keeps working (and renews it). A command without a lease id, or with one that
is not the current lease, is refused (``LeaseRequired`` / ``LeaseHeld``); nobody gets
control by default.

Thread-safe: the HTTP server's threads and viser's threads call it concurrently.
"""

from __future__ import annotations

import ipaddress
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass


class ControlRefused(Exception):
    """A command was not allowed to run; the message says what the client must do."""


class TokenRequired(ControlRefused):
    """The token is missing or wrong (HTTP 401)."""


class LeaseRequired(ControlRefused):
    """No lease id, or one that was never issued or has been released (HTTP 409)."""


class LeaseHeld(ControlRefused):
    """Another client holds the control lease (HTTP 409)."""


@dataclass(frozen=True)
class LeaseView:
    """The public view of the lease: nothing in it lets a client act as the holder.

    held: someone holds control now (not lapsed); holder: the display name they gave (a
    label only, never authority); since_s: wall-clock time [s since the epoch] the lease was
    taken; idle_s: seconds since its last command.
    """

    held: bool
    holder: str | None = None
    since_s: float | None = None
    idle_s: float | None = None


@dataclass
class _Lease:
    lease_id: str
    holder: str
    since_s: float  # wall clock, for people
    last_used_s: float  # monotonic, for the timeout


def _same(supplied: str | None, secret: str) -> bool:
    return bool(supplied) and secrets.compare_digest(str(supplied).encode(), secret.encode())


def token_ok(expected: str | None, supplied: str | None) -> bool:
    """True when no token is set (``expected`` None) or ``supplied`` is it, compared in
    constant time. The one token comparison of the HTTP routes, the request-limits
    middleware and the 3D scene."""
    return expected is None or (
        supplied is not None and secrets.compare_digest(supplied.encode(), expected.encode())
    )


def is_loopback(host: str) -> bool:
    """True for addresses only this machine can reach: 127.0.0.0/8, ::1 and localhost."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class Authority:
    """The token (None: none set) and the one control lease; see the module docstring."""

    def __init__(
        self,
        token: str | None,
        timeout_s: float,
        clock: Callable[[], float] = time.monotonic,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        self.token = token
        self.timeout_s = timeout_s
        self._clock = clock
        self._wall_clock = wall_clock
        self._lease: _Lease | None = None
        self._lock = threading.Lock()

    @property
    def token_required(self) -> bool:
        return self.token is not None

    def token_ok(self, supplied: str | None) -> bool:
        """True when no token is set or ``supplied`` is it (compared in constant time)."""
        return token_ok(self.token, supplied)

    def require_token(self, supplied: str | None) -> None:
        if not self.token_ok(supplied):
            raise TokenRequired("missing or wrong token (Authorization: Bearer <token>)")

    def take(self, holder: str, take_over: bool = False) -> str:
        """A new lease for ``holder`` (a display name); its id, to send with each command.

        Raises LeaseHeld when another lease is active and ``take_over`` is false. Taking
        control again while holding it also issues a new id (the old one stops working).
        """
        return self.take_from(holder, take_over)[0]

    def take_from(self, holder: str, take_over: bool = False) -> tuple[str, LeaseView]:
        """:meth:`take`, also saying whom it took control from: the public view of the lease
        it replaced (``held`` false when control was free or its lease had lapsed)."""
        with self._lock:
            current = self._lease
            active = current is not None and self._active(current)
            if current is not None and active and not take_over:
                raise LeaseHeld(f"{self._held_by(current)}; take it with take_over=true")
            previous = LeaseView(held=False)
            if current is not None and active:
                idle = self._clock() - current.last_used_s
                previous = LeaseView(True, current.holder, current.since_s, idle)
            lease_id = secrets.token_urlsafe(24)
            self._lease = _Lease(lease_id, holder, self._wall_clock(), self._clock())
            return lease_id, previous

    def check(self, lease_id: str | None) -> str:
        """Allow one command from the holder of ``lease_id`` and renew the lease.

        Returns the holder's display name. Raises LeaseRequired when no lease id is given or
        nobody holds control, LeaseHeld when another client holds it.
        """
        with self._lock:
            current = self._lease
            if current is not None and _same(lease_id, current.lease_id):
                current.last_used_s = self._clock()
                return current.holder
            if current is not None and self._active(current):
                raise LeaseHeld(
                    f"{self._held_by(current)}; POST /api/lease with take_over=true to take it"
                )
            what = "no lease id sent" if not lease_id else "that lease is no longer valid"
            raise LeaseRequired(
                f"{what}: take control first (POST /api/lease, then send its lease_id "
                "in the X-Lease header)"
            )

    def holds(self, lease_id: str | None) -> bool:
        """True when ``lease_id`` is the current lease (does not renew it)."""
        with self._lock:
            current = self._lease
            return current is not None and _same(lease_id, current.lease_id)

    def active(self, lease_id: str | None) -> bool:
        """True while ``lease_id`` is the current lease and has not lapsed (no renewal)."""
        with self._lock:
            current = self._lease
            return (
                current is not None and _same(lease_id, current.lease_id) and self._active(current)
            )

    def release(self, lease_id: str | None) -> bool:
        """Give control back; True when ``lease_id`` was the current lease."""
        with self._lock:
            if self._lease is not None and _same(lease_id, self._lease.lease_id):
                self._lease = None
                return True
            return False

    def view(self) -> LeaseView:
        with self._lock:
            current = self._lease
            if current is None or not self._active(current):
                return LeaseView(held=False)
            idle = self._clock() - current.last_used_s
            return LeaseView(True, current.holder, current.since_s, idle)

    def _active(self, lease: _Lease) -> bool:
        return self._clock() - lease.last_used_s < self.timeout_s

    def _held_by(self, lease: _Lease) -> str:
        since = time.strftime("%H:%M:%S", time.localtime(lease.since_s))
        return f"control is held by {lease.holder!r} since {since}"

"""The link between a station and a robot node: its keys, its messages and its errors.

Both sides speak it, over Eclipse Zenoh (app/link/zenoh_link.py) or, in one process, by
calling each other (app/link/local.py). Every key is under one prefix (``link.key_prefix``,
default ``deltadash/robot``); ROS 2 topics (issue 31) live beside it under their own keys
(``<domain>/<topic>/<type>/<hash>``), so one Zenoh network carries both.

- ``state``: the loop's :class:`~app.control.state.Snapshot` after each tick; put,
  latest only (congestion drops it; express).
- ``ticks``: every tick's snapshot, in batches, while a station taps them (a run's
  log); put, reliable (congestion blocks the publisher's thread, never the loop's).
- ``cmd/<op>``: a command; a query whose payload is the op's JSON arguments, answered
  with its reply.
- ``heartbeat/<station>``: a station is alive; put every ``link.heartbeat_s``.
- ``node``: the node's own status (the link's holder, take-overs, losses); put once a
  second.
- ``alive``: the node's liveliness token.

A command names its station in the query's parameters (``?station=<id>;seq=<n>;mac=<hex>``);
the node takes commands only from the station that holds its link (``cmd/link``), signed
with the key the node gave it then (:func:`sign`), but an e-stop from anyone. Heartbeats
are signed the same way (``<seq>:<mac>``). A reply is ``{"ok": true, "result": ...}``
or ``{"ok": false, "error": {"kind", "message", ...}}`` with the same kinds the API maps
to HTTP codes (422 ``rejected``, 409 ``refused`` and ``link``, 503 ``bus`` /
``offline`` / ``timeout``), so a refusal that crossed the link reads as it did in one
process.
"""

from __future__ import annotations

import hashlib
import hmac
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.control.errors import GoalRejected, MotionRefused
from hardware.errors import BusError

DEFAULT_PREFIX = "deltadash/robot"
MAX_COMMAND_BYTES = 32 << 20  # a command's arguments; a larger one is refused unread
PROTOCOL = 1  # bumped when a message changes shape; a node refuses another station's


@dataclass(frozen=True)
class Keys:
    """The key expressions of one robot node (``prefix``: ``link.key_prefix``)."""

    prefix: str = DEFAULT_PREFIX

    @property
    def state(self) -> str:
        return f"{self.prefix}/state"

    @property
    def ticks(self) -> str:
        return f"{self.prefix}/ticks"

    @property
    def node(self) -> str:
        return f"{self.prefix}/node"

    @property
    def alive(self) -> str:
        return f"{self.prefix}/alive"

    @property
    def commands(self) -> str:
        return f"{self.prefix}/cmd/*"

    def command(self, op: str) -> str:
        return f"{self.prefix}/cmd/{op}"

    @property
    def heartbeats(self) -> str:
        return f"{self.prefix}/heartbeat/*"

    def heartbeat(self, station: str) -> str:
        return f"{self.prefix}/heartbeat/{station}"


def sign(key: bytes, station: str, op: str, seq: int, body: bytes = b"") -> str:
    """The holder's signature of one message: HMAC-SHA256 with the link's key (given to
    the station alone, in the answer to its ``link``) over its station, op, sequence
    number and body. A command (or a heartbeat: op ``heartbeat``) carries ``seq`` and this
    ``mac``; the node takes it only from the holder, only once (``seq`` grows), and only
    unchanged. A peer that reads the holder's id, a heartbeat or a command cannot forge
    or replay one."""
    head = f"{station}|{op}|{seq}|".encode()
    return hmac.new(key, head + body, hashlib.sha256).hexdigest()


def signed(key: bytes, station: str, op: str, seq: int, body: bytes, mac: str) -> bool:
    """``mac`` is :func:`sign`'s for this message (compared in constant time)."""
    return hmac.compare_digest(sign(key, station, op, seq, body), mac)


class LinkRefused(MotionRefused):
    """A command from a station that does not hold the robot node's link (HTTP 409);
    ``holder``: the station that holds it (None: nobody, the link may be taken)."""

    def __init__(self, message: str, holder: str | None = None) -> None:
        super().__init__(message)
        self.holder = holder


class RobotOffline(RuntimeError):
    """The robot node does not answer: not started, gone, or the link is down (HTTP 503)."""


class LinkTimeout(TimeoutError):
    """A command the robot node did not answer in time (HTTP 503)."""


class RemoteError(RuntimeError):
    """A failure on the robot node with no kind of its own (a bug there): its message."""


def error_of(exc: BaseException) -> dict[str, Any]:
    """The wire form of a refused command's exception: ``kind`` and ``message``, and for a
    rejected goal its ``reason``, ``nearest_m``, ``goal_m`` and ``phi_rad``."""
    if isinstance(exc, GoalRejected):
        return {
            "kind": "rejected",
            "message": str(exc),
            "reason": exc.reason,
            "nearest_m": None if exc.nearest is None else [float(v) for v in exc.nearest],
            "goal_m": None if exc.goal is None else [float(v) for v in exc.goal],
            "phi_rad": float(exc.phi),
        }
    if isinstance(exc, LinkRefused):
        return {"kind": "link", "message": str(exc), "holder": exc.holder}
    kinds: list[tuple[type[BaseException], str]] = [
        (LinkRefused, "link"),
        (MotionRefused, "refused"),
        (BusError, "bus"),
        (TimeoutError, "timeout"),
        (RobotOffline, "offline"),
        (KeyError, "invalid"),
        (ValueError, "invalid"),
        (TypeError, "invalid"),
    ]
    for cls, kind in kinds:
        if isinstance(exc, cls):
            message = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
            return {"kind": kind, "message": str(message)}
    return {"kind": "error", "message": f"{type(exc).__name__}: {exc}"}


def exception_of(error: dict[str, Any]) -> BaseException:
    """The exception a station raises for a refusal's wire form (:func:`error_of`)."""
    kind, message = error.get("kind"), str(error.get("message", ""))
    if kind == "rejected":
        nearest, goal = error.get("nearest_m"), error.get("goal_m")
        return GoalRejected(
            str(error.get("reason", message)),
            None if nearest is None else np.asarray(nearest, dtype=float),
            None if goal is None else np.asarray(goal, dtype=float),
            float(error.get("phi_rad") or 0.0),
        )
    if kind == "link":
        holder = error.get("holder")
        return LinkRefused(message, None if holder is None else str(holder))
    if kind == "refused":
        return MotionRefused(message)
    if kind == "bus":
        return BusError((), "robot node", message)
    if kind == "timeout":
        return LinkTimeout(message)
    if kind == "offline":
        return RobotOffline(message)
    if kind == "invalid":
        return ValueError(message)
    return RemoteError(message)


def reply_ok(result: Any = None) -> bytes:
    """An accepted command's reply: its result as plain JSON data."""
    return json.dumps({"ok": True, "result": result}, separators=(",", ":")).encode()


def reply_error(exc: BaseException) -> bytes:
    """A refused command's reply."""
    return json.dumps({"ok": False, "error": error_of(exc)}, separators=(",", ":")).encode()


def read_reply(payload: bytes) -> Any:
    """A reply's result; raises the refusal's exception (:func:`exception_of`)."""
    try:
        message = json.loads(payload)
    except ValueError as exc:
        raise RemoteError(f"the robot node answered something that is not JSON: {exc}") from None
    if not isinstance(message, dict) or "ok" not in message:
        raise RemoteError(f"the robot node answered without an outcome: {message!r:.200}")
    if message["ok"]:
        return message.get("result")
    raise exception_of(message.get("error") or {})

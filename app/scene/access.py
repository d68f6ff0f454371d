"""Who may command the robot from the 3D scene: per browser, the token and its own lease.

viser has no authentication, and every browser (or plain WebSocket client) on its port
sees the same panel. So each connected client gets its own "Control" folder (viser's
per-client GUI, ``client.gui``): a token field when a token is set, and buttons to take
and give back control. The panel's commands (torque, jog, goal drag, go-to, reset, run
start and abort) ask ``SceneAccess.allow(client_id)`` before acting: the client must have
entered the token, and it must hold the control lease of the one ``Authority``
(app/control/authority.py) that the HTTP API checks too. Its first command takes the lease
when nobody holds it; taking it from another holder needs the "Take control" button. The
lease id stays on the server, per viser client. E-stop needs none of this.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import viser

from app.control.authority import Authority, ControlRefused, LeaseHeld

LOCKED = "locked: enter the server's token in Control ▸ Token and press Unlock"


@dataclass
class _Client:
    """One viser client's access: unlocked by the token, its lease id, its GUI handles."""

    name: str
    unlocked: bool
    lease_id: str | None = None
    message: str = ""
    refused: int = 0  # commands refused so far (what tests wait on)
    handles: dict[str, Any] = field(default_factory=dict)


class SceneAccess:
    """Per-client token and lease for the scene's controls (see the module docstring).

    server: the viser server (None: no GUI, for tests that drive ``connect`` by hand);
    authority: the app's ``Authority``, shared with the HTTP API.
    """

    def __init__(self, server: viser.ViserServer | None, authority: Authority) -> None:
        self.authority = authority
        self._clients: dict[int, _Client] = {}
        self._lock = threading.Lock()
        if server is not None:
            server.on_client_connect(self._on_connect)
            server.on_client_disconnect(self._on_disconnect)

    # ---- clients come and go (viser's threads) ----
    def connect(self, client_id: int) -> _Client:
        """Register a client (locked when a token is set) without GUI; returns its record."""
        client = _Client(f"scene client {client_id}", not self.authority.token_required)
        with self._lock:
            self._clients[client_id] = client
        return client

    def disconnect(self, client_id: int) -> None:
        """Forget a client and give back its lease: a closed tab holds no control."""
        with self._lock:
            client = self._clients.pop(client_id, None)
        if client is not None:
            self.authority.release(client.lease_id)

    def _on_connect(self, handle: viser.ClientHandle) -> None:
        client = self.connect(handle.client_id)
        gui = handle.gui
        with gui.add_folder("Control", order=-1.0):
            client.handles["status"] = gui.add_markdown(self._status(client))
            if self.authority.token_required:
                token = gui.add_text("Token", "", hint="the server's token (--token)")
                unlock = gui.add_button("Unlock", icon=viser.Icon.LOCK_OPEN)
                unlock.on_click(lambda _: self._unlock_from_field(handle.client_id, token))
                client.handles.update(token=token, unlock=unlock)
            take = gui.add_button("Take control", icon=viser.Icon.HAND_GRAB)
            give = gui.add_button("Give back control", icon=viser.Icon.HAND_OFF)
        take.on_click(lambda _: self._take_over(handle.client_id))
        give.on_click(lambda _: self.give_back(handle.client_id))
        client.handles.update(take=take, give_back=give)

    def _on_disconnect(self, handle: viser.ClientHandle) -> None:
        self.disconnect(handle.client_id)

    def _unlock_from_field(self, client_id: int, field_handle: Any) -> None:
        supplied, field_handle.value = field_handle.value, ""  # never left on screen
        self.unlock(client_id, supplied)

    # ---- what the operator does in the Control folder ----
    def unlock(self, client_id: int, supplied: str) -> bool:
        """Unlock this client's controls if ``supplied`` is the token."""
        client = self._client(client_id)
        if client is None:
            return False
        client.unlocked = self.authority.token_ok(supplied.strip())
        self._say(client, "" if client.unlocked else "wrong token")
        return client.unlocked

    def take(self, client_id: int, take_over: bool = False) -> bool:
        """Take the lease for this client (from another holder only with ``take_over``)."""
        client = self._client(client_id)
        if client is None:
            return False
        if not client.unlocked:
            self._say(client, LOCKED)
            return False
        try:
            client.lease_id = self.authority.take(client.name, take_over)
        except LeaseHeld as exc:
            self._say(client, f"{exc}: press Control ▸ Take control to take it over")
            return False
        self._say(client, "")
        return True

    def _take_over(self, client_id: int) -> None:
        self.take(client_id, take_over=True)

    def give_back(self, client_id: int) -> None:
        client = self._client(client_id)
        if client is not None:
            self.authority.release(client.lease_id)
            client.lease_id = None
            self._say(client, "")

    # ---- the check every scene command passes ----
    def allow(self, client_id: int | None) -> bool:
        """May this client command the robot now? Renews its lease; when it holds none and
        nobody else does, takes one. A refusal is shown in that client's Control folder."""
        client = self._client(client_id) if client_id is not None else None
        if client is None or client_id is None:
            return False  # not a connected client: nobody to answer, nothing to move
        allowed = self._allow(client, client_id)
        client.refused += not allowed
        return allowed

    def _allow(self, client: _Client, client_id: int) -> bool:
        if not client.unlocked:
            self._say(client, LOCKED)
            return False
        if client.lease_id is None and not self.take(client_id):
            return False
        try:
            self.authority.check(client.lease_id)
        except LeaseHeld as exc:
            self._say(client, f"{exc}; press Control ▸ Take control to take it over")
            return False
        except ControlRefused:  # released or replaced: take a fresh one if control is free
            client.lease_id = None
            return self.take(client_id)
        if client.message:
            self._say(client, "")
        return True

    def guarded(self, action: Callable[[Any], None]) -> Callable[[Any], None]:
        """A viser callback that runs ``action(event)`` only when ``allow`` lets the
        event's client command the robot."""

        def callback(event: Any) -> None:
            if self.allow(getattr(event, "client_id", None)):
                action(event)

        return callback

    def message(self, client_id: int) -> str:
        """The last refusal shown to this client ("" when none)."""
        client = self._client(client_id)
        return client.message if client is not None else ""

    def refused(self, client_id: int) -> int:
        """How many of this client's commands were refused."""
        client = self._client(client_id)
        return client.refused if client is not None else 0

    def handle(self, client_id: int, name: str) -> Any:
        """One of this client's own GUI handles: "status", "token", "unlock", "take",
        "give_back" (None before its Control folder is built)."""
        client = self._client(client_id)
        return client.handles.get(name) if client is not None else None

    def unlocked(self, client_id: int) -> bool:
        """Has this client entered the token (always, when none is set)?"""
        client = self._client(client_id)
        return client is not None and client.unlocked

    def holds(self, client_id: int) -> bool:
        client = self._client(client_id)
        return client is not None and self.authority.holds(client.lease_id)

    def _client(self, client_id: int) -> _Client | None:
        with self._lock:
            return self._clients.get(client_id)

    def _status(self, client: _Client) -> str:
        state = "unlocked" if client.unlocked else "🔒 locked"
        if self.authority.holds(client.lease_id):
            state += " · **you hold control**"
        lines = [f"**Control**: {state}"]
        if client.message:
            lines.append(f"_{client.message}_")
        return "  \n".join(lines)

    def _say(self, client: _Client, message: str) -> None:
        client.message = message
        status = client.handles.get("status")
        if status is not None:
            status.content = self._status(client)

"""The Host and Origin checks on the 3D scene's port (app/origins.py says why and what).

viser serves its page and its WebSocket on one port with the ``websockets`` library and
checks neither header, so a page of any site could open the scene's WebSocket, read the
robot's pose and, with no token set, press the panel's buttons. viser has no hook for
this; ``websockets.asyncio.server.serve`` does (``process_request``, called for every
HTTP request and WebSocket handshake before anything else). :func:`guarded_viser_server`
starts a ``ViserServer`` whose ``serve`` call puts the policy's check in front of viser's
own ``process_request``: a refused request gets 403 with the reason, and never reaches
viser. If viser ever starts its server another way, the check would be missing, so the
scene is then refused instead of served unguarded (RuntimeError).
"""

from __future__ import annotations

import functools
import http
import threading
from typing import Any

import viser
import viser.infra._infra as viser_infra

from app.origins import OriginPolicy

_lock = threading.Lock()  # one guarded start at a time: the hook is swapped in for it


class _Websockets:
    """The ``websockets`` package as viser's server module sees it during one start: the
    same, but ``asyncio.server.serve`` adds the policy's check (``guard``)."""

    def __init__(self, real: Any, guard: Any) -> None:
        self._real = real
        self.installed = False
        server = _Namespace(real.asyncio.server, serve=self._serve)
        self.asyncio = _Namespace(real.asyncio, server=server)
        self._guard = guard

    def _serve(self, *args: Any, **kwargs: Any) -> Any:
        kwargs["process_request"] = functools.partial(self._guard, kwargs.get("process_request"))
        self.installed = True
        return self._real.asyncio.server.serve(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._real, name)


class _Namespace:
    """A module's attributes, with some replaced."""

    def __init__(self, real: Any, **replaced: Any) -> None:
        self._real = real
        self.__dict__.update(replaced)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._real, name)


def check_request(policy: OriginPolicy, connection: Any, request: Any) -> Any:
    """``process_request`` of a ``websockets`` server: a 403 response naming the reason
    when ``policy`` refuses the request's Host or Origin, else None (go on)."""
    hosts = request.headers.get_all("Host")
    origins = request.headers.get_all("Origin")
    if len(hosts) > 1 or len(origins) > 1:
        reason: str | None = "more than one Host or Origin header"
    else:
        reason = policy.refusal(hosts[0] if hosts else None, origins[0] if origins else None)
    if reason is None:
        return None
    return connection.respond(http.HTTPStatus.FORBIDDEN, f"{reason}\n")


def guarded_viser_server(policy: OriginPolicy, **kwargs: Any) -> viser.ViserServer:
    """A started ``viser.ViserServer(**kwargs)`` whose port refuses what ``policy`` refuses.

    Raises RuntimeError (the server stopped again) when the check could not be put in.
    """

    def guard(inner: Any, connection: Any, request: Any) -> Any:
        refused = check_request(policy, connection, request)
        if refused is not None or inner is None:
            return refused
        return inner(connection, request)

    with _lock:
        real = viser_infra.websockets
        shim = _Websockets(real, guard)
        viser_infra.websockets = shim  # type: ignore[assignment]
        try:
            server = viser.ViserServer(**kwargs)  # returns once it serves
        finally:
            viser_infra.websockets = real
    if not shim.installed:
        server.stop()
        raise RuntimeError(
            "the 3D scene's Host/Origin check could not be installed in this viser version; "
            "the scene is not served (set server.scene = false, or report it)"
        )
    return server

"""The Host and Origin checks on the HTTP port (app/origins.py says why and what passes).

:class:`OriginCheck` is an ASGI middleware inside :class:`~app.server.estop.EstopFirst`:
an e-stop is still latched from anywhere (it moves nothing and reads nothing), while every
other request and WebSocket from a page of another site, or under a host name that is not
this machine's, is refused before the token, the body or a route: HTTP gets 403 with a
``detail`` naming the header and the reason, a WebSocket is closed before it is accepted
(the browser sees 403).
"""

from __future__ import annotations

import json
import logging

from starlette.types import ASGIApp, Receive, Scope, Send

from app.origins import OriginPolicy
from app.server.limits import OPEN_TO_ALL

log = logging.getLogger(__name__)


class OriginCheck:
    """ASGI middleware: refuse requests and WebSockets that :class:`OriginPolicy` refuses."""

    def __init__(self, app: ASGIApp, policy: OriginPolicy) -> None:
        self.app = app
        self.policy = policy
        self.refused = 0  # requests refused so far (logged once per reason kind)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket") or scope["path"] in OPEN_TO_ALL:
            await self.app(scope, receive, send)
            return
        reason = self.policy.refusal_of_headers(scope.get("headers", ()))
        if reason is None:
            await self.app(scope, receive, send)
            return
        self.refused += 1
        if self.refused == 1 or self.refused % 100 == 0:
            log.warning("refused %s %s (%d so far): %s", kind, scope["path"], self.refused, reason)
        if kind == "websocket":
            await receive()  # websocket.connect
            await send({"type": "websocket.close", "code": 1008, "reason": reason[:120]})
            return
        body = json.dumps({"detail": reason}).encode()
        headers = [(b"content-type", b"application/json"), (b"content-length", b"%d" % len(body))]
        await send({"type": "http.response.start", "status": 403, "headers": headers})
        await send({"type": "http.response.body", "body": body})

"""The station's early e-stop path: ``POST /api/estop`` latched before the routes' work.

Measured on the loaded 2-core machine (docs/dashboard.md, "The e-stop"), a press reached
``POST /api/estop``'s handler a few hundred ms after the input: the request waited in the
asyncio event loop behind the telemetry WebSocket, status polls and program checks, then
through routing and the dependencies. :class:`EstopFirst`, the outermost ASGI middleware,
sends the e-stop as soon as uvicorn hands the request to the app, before the token and
body checks, routing and dependencies; the route then answers with that same command's
outcome (it stays the documented API, with its response model).

The page's other path does not pass through the station at all: the robot node's own
listener (app/robot/estop.py), to which the page posts the same press beside this one.
"""

from __future__ import annotations

from starlette.types import ASGIApp, Receive, Scope, Send

from app.robot.estop import (  # noqa: F401  (the station's receipts are the same record)
    EstopReceipt,
    EstopReceipts,
    merged,
    press_id,
    valid_press,
)

ESTOP_PATH = "/api/estop"
SCOPE_KEY = "deltadash.estop"  # the latched command's Future, for the route


class EstopFirst:
    """ASGI middleware, outermost of the project's: a ``POST /api/estop`` calls the app's
    ``EstopReceipts.press("middleware", press)`` before anything else runs for it,
    and leaves the command's Future in the scope (``SCOPE_KEY``) for the route to answer
    with. Everything else passes untouched."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["method"] == "POST" and scope["path"] == ESTOP_PATH:
            app = scope.get("app")  # Starlette puts itself there before its middleware
            receipts = getattr(app.state, "estop_receipts", None) if app is not None else None
            if receipts is not None and receipts.controller.running:
                press = press_id(scope.get("query_string", b""))
                scope[SCOPE_KEY] = receipts.press("middleware", press)
        await self.app(scope, receive, send)

"""Typed dependencies: the controller, the token check and the control lease."""

from __future__ import annotations

import secrets
import time
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Header, HTTPException, Request, WebSocket

from app.config import Settings
from app.control.controller import Controller


def get_controller(request: Request) -> Controller:
    return request.app.state.controller


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def token_ok(settings: Settings, supplied: str | None) -> bool:
    """True when no token is configured or ``supplied`` matches it."""
    expected = settings.server.token
    return expected is None or (
        supplied is not None and secrets.compare_digest(supplied.encode(), expected.encode())
    )


def _bearer(authorization: str | None) -> str | None:
    if authorization and authorization.lower().startswith("bearer "):
        return authorization[7:].strip()
    return authorization


def require_token(request: Request, authorization: Annotated[str | None, Header()] = None) -> None:
    """Control requests carry ``Authorization: Bearer <token>`` when a token is set."""
    if not token_ok(request.app.state.settings, _bearer(authorization)):
        raise HTTPException(401, "missing or wrong token (Authorization: Bearer <token>)")


def websocket_token_ok(websocket: WebSocket) -> bool:
    supplied = websocket.query_params.get("token") or _bearer(
        websocket.headers.get("authorization")
    )
    return token_ok(websocket.app.state.settings, supplied)


@dataclass
class Lease:
    """Which client holds control, until when (monotonic seconds)."""

    holder: str | None = None
    expires_s: float = 0.0

    def active(self) -> bool:
        return self.holder is not None and time.monotonic() < self.expires_s

    def renew(self, client: str, timeout_s: float) -> None:
        self.holder, self.expires_s = client, time.monotonic() + timeout_s


def require_lease(
    request: Request,
    _: Annotated[None, Depends(require_token)],
    x_client: Annotated[str | None, Header()] = None,
) -> str:
    """One client controls at a time; its lease renews with each control request."""
    lease: Lease = request.app.state.lease
    client = x_client or "anonymous"
    if lease.active() and lease.holder != client:
        raise HTTPException(
            409,
            f"control is held by {lease.holder!r}; POST /api/lease with take_over=true to take it",
        )
    lease.renew(client, request.app.state.settings.server.lease_timeout_s)
    return client


ControllerDep = Annotated[Controller, Depends(get_controller)]
ControlClient = Annotated[str, Depends(require_lease)]
TokenChecked = Annotated[None, Depends(require_token)]

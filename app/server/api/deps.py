"""Typed dependencies: what routes read from ``app.state`` (controller, runs, world, scene,
settings, lease), the token check and the control lease. Only this module reads
``app.state``; routes declare what they need as ``Annotated[..., Depends(...)]`` aliases."""

from __future__ import annotations

import secrets
import time
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Header, HTTPException, WebSocket
from starlette.requests import HTTPConnection

from app.config import Settings
from app.control.controller import Controller
from app.runs.manager import RunManager
from app.scene import Scene
from app.world.service import WorldService


def get_controller(connection: HTTPConnection) -> Controller:
    """The control loop; 503 when it is not running (before startup, after shutdown)."""
    controller: Controller = connection.app.state.controller
    if not controller.running:
        raise HTTPException(503, "the control loop is not running")
    return controller


def get_settings(connection: HTTPConnection) -> Settings:
    return connection.app.state.settings


def get_runs(connection: HTTPConnection) -> RunManager:
    return connection.app.state.runs


def get_world(connection: HTTPConnection) -> WorldService:
    return connection.app.state.world


def get_scene(connection: HTTPConnection) -> Scene | None:
    """The 3D scene, None when the config turns it off."""
    return getattr(connection.app.state, "scene", None)


def get_lease(connection: HTTPConnection) -> Lease:
    return connection.app.state.lease


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


def require_token(
    settings: Annotated[Settings, Depends(get_settings)],
    authorization: Annotated[str | None, Header()] = None,
) -> None:
    """Control requests carry ``Authorization: Bearer <token>`` when a token is set."""
    if not token_ok(settings, _bearer(authorization)):
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
    lease: Annotated[Lease, Depends(get_lease)],
    settings: Annotated[Settings, Depends(get_settings)],
    _: Annotated[None, Depends(require_token)],
    x_client: Annotated[str | None, Header()] = None,
) -> str:
    """One client controls at a time; its lease renews with each control request."""
    client = x_client or "anonymous"
    if lease.active() and lease.holder != client:
        raise HTTPException(
            409,
            f"control is held by {lease.holder!r}; POST /api/lease with take_over=true to take it",
        )
    lease.renew(client, settings.server.lease_timeout_s)
    return client


ControllerDep = Annotated[Controller, Depends(get_controller)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
RunsDep = Annotated[RunManager, Depends(get_runs)]
WorldDep = Annotated[WorldService, Depends(get_world)]
SceneDep = Annotated[Scene | None, Depends(get_scene)]
LeaseDep = Annotated[Lease, Depends(get_lease)]
ControlClient = Annotated[str, Depends(require_lease)]
TokenChecked = Annotated[None, Depends(require_token)]

"""Telemetry WebSocket: the loop's state at a steady rate (default 50 Hz)."""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from app.server.api import serialize
from app.server.api.deps import websocket_token_ok

router = APIRouter(tags=["telemetry"])


@router.websocket("/telemetry")
async def telemetry(websocket: WebSocket) -> None:
    """Stream snapshots as JSON; ``?hz=`` sets the rate (1-200, default from config)."""
    if not websocket_token_ok(websocket):
        await websocket.close(code=1008, reason="missing or wrong token (?token=)")
        return
    settings = websocket.app.state.settings
    try:
        hz = float(websocket.query_params.get("hz", settings.server.telemetry_hz))
    except ValueError:
        hz = settings.server.telemetry_hz
    period = 1.0 / min(max(hz, 1.0), 200.0)
    controller = websocket.app.state.controller
    await websocket.accept()
    last_tick = -1
    try:
        while True:
            snap = controller.snapshot()
            if snap.tick != last_tick:
                last_tick = snap.tick
                await websocket.send_json(serialize.telemetry(snap, controller))
            await asyncio.sleep(period)
    except (WebSocketDisconnect, RuntimeError):
        return

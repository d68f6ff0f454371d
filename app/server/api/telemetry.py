"""Telemetry WebSocket: the loop's state at a steady rate (default 50 Hz).

WebSockets are not in OpenAPI; ``GET /api/telemetry`` answers the latest message, so the
message's schema (``TelemetryMessage``) is in /openapi.json and a client can poll it."""

from __future__ import annotations

import asyncio
import math
from typing import Any

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from app.server.api import serialize
from app.server.api.deps import ControllerDep, SettingsDep, websocket_token_ok
from app.server.api.responses import TelemetryMessage
from app.server.errors import UNAVAILABLE

router = APIRouter(tags=["telemetry"])


@router.get("/telemetry", response_model=TelemetryMessage, responses=UNAVAILABLE)
def latest_telemetry(controller: ControllerDep) -> dict[str, Any]:
    """The latest telemetry message: the same JSON the WebSocket streams, once."""
    return serialize.telemetry(controller.snapshot())


@router.websocket("/telemetry")
async def telemetry(websocket: WebSocket, controller: ControllerDep, settings: SettingsDep) -> None:
    """Stream snapshots as JSON; ``?hz=`` sets the rate (1-200, default from config)."""
    if not websocket_token_ok(websocket):
        # accepted, then closed with the policy code: a close before the accept is an HTTP
        # 403 to the browser, whose close event then says only 1006 (no reason), and the
        # page could not tell that it should ask for the token
        await websocket.accept()
        await websocket.close(code=1008, reason="missing or wrong token (?token=)")
        return
    hz = stream_rate_hz(websocket.query_params.get("hz"), settings.server.telemetry_hz)
    clock = asyncio.get_running_loop().time
    await websocket.accept()
    pacer = Pacer(1.0 / hz, clock())
    last_tick = -1
    try:
        while True:
            snap = controller.snapshot()
            if snap.tick != last_tick:
                last_tick = snap.tick
                await websocket.send_json(serialize.telemetry(snap))
            await asyncio.sleep(max(0.0, pacer.next(clock()) - clock()))
    except (WebSocketDisconnect, RuntimeError):
        return


def stream_rate_hz(asked: str | None, default_hz: float) -> float:
    """``?hz=`` clamped to 1-200 Hz; the default for a missing or non-numeric value, and
    for NaN (which would compare as neither too low nor too high: no pacing at all)."""
    try:
        hz = float(asked) if asked is not None else default_hz
    except ValueError:
        hz = default_hz
    return min(max(hz, 1.0), 200.0) if not math.isnan(hz) else default_hz


class Pacer:
    """Send times on a fixed grid, start + k period: a message's own send time does not
    push the next one back (sleeping a period after each send gave 33 msg/s for 50), and
    a client that falls behind skips the missed slots instead of getting a burst."""

    def __init__(self, period_s: float, start_s: float) -> None:
        self.period_s, self.start_s, self.slot = period_s, start_s, 0

    def next(self, now_s: float) -> float:
        """The next send time [s] after the one just done, at ``now_s`` [s]."""
        self.slot += 1
        behind = now_s - (self.start_s + self.slot * self.period_s)
        if behind > 1e-6 * self.period_s:  # a slot due now (to rounding) is not missed
            self.slot += math.ceil(behind / self.period_s - 1e-6)
        return self.start_s + self.slot * self.period_s

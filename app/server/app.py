"""The FastAPI application: its lifespan owns the bus and the control loop.

Startup opens the configured backend (simulator, emulator or real servos) and starts the
controller's thread; shutdown stops motion, relaxes the servos per config and closes the
bus. Errors map to HTTP codes in one place: a bad goal is 422, a robot that cannot move
now is 409, a bus that does not answer is 503; never a 500 for operator input.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import sys
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles

from app.config import Settings
from app.control.commands import MotionRefused
from app.control.controller import Controller
from app.control.gate import GoalRejected
from app.runs.manager import RunManager
from app.scene import start_scene
from app.server.api import dashboard, mav, robot, runs, telemetry
from app.server.api.deps import Lease
from app.server.api.serialize import floats
from app.server.backends import open_backend
from app.world.service import WorldService
from hardware.errors import BusError

GIL_SWITCH_S = 2.5e-4
STATIC_DIR = Path(__file__).resolve().parents[2] / "static"


def _error(status: int, detail: str, **extra: Any) -> JSONResponse:
    return JSONResponse({"detail": detail, **extra}, status_code=status)


def _field_errors(exc: RequestValidationError) -> str:
    """'position_m.1: Input should be a finite number' per error; never echoes raw input."""
    parts = []
    for error in exc.errors():
        location = ".".join(str(p) for p in error["loc"] if p != "body") or "body"
        parts.append(f"{location}: {error['msg']}")
    return "; ".join(parts)


def _install_error_handlers(app: FastAPI) -> None:
    @app.exception_handler(RequestValidationError)
    async def invalid_request(_: Request, exc: RequestValidationError) -> JSONResponse:
        return _error(422, _field_errors(exc))

    @app.exception_handler(GoalRejected)
    async def goal_rejected(_: Request, exc: GoalRejected) -> JSONResponse:
        nearest = None if exc.nearest is None else floats(exc.nearest)
        return _error(422, str(exc), nearest_m=nearest)

    @app.exception_handler(MotionRefused)
    async def motion_refused(_: Request, exc: MotionRefused) -> JSONResponse:
        return _error(409, str(exc))

    @app.exception_handler(BusError)
    async def bus_error(_: Request, exc: BusError) -> JSONResponse:
        return _error(503, f"servo bus: {exc}")

    @app.exception_handler(TimeoutError)
    async def timeout(_: Request, exc: TimeoutError) -> JSONResponse:
        return _error(503, "the control loop did not answer in time")

    @app.exception_handler(RuntimeError)
    async def runtime(_: Request, exc: RuntimeError) -> JSONResponse:
        return _error(503, str(exc))

    @app.exception_handler(ValueError)
    async def value_error(_: Request, exc: ValueError) -> JSONResponse:
        return _error(422, str(exc))


def create_app(settings: Settings, backend_opener: Callable = open_backend) -> FastAPI:
    """The app for ``settings``; ``backend_opener`` is swappable for tests."""

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        # The control thread must get the GIL back within a fraction of a tick when it wakes;
        # CPython's default switch interval (5 ms) let other threads delay ticks that long.
        sys.setswitchinterval(GIL_SWITCH_S)
        # A full garbage collection stops every thread; over the startup heap (viser,
        # mujoco, FastAPI) it took tens of ms. Freeze what exists now so later collections
        # only walk new objects.
        gc.collect()
        gc.freeze()
        with backend_opener(settings) as backend:
            controller = Controller(settings, backend.bus, backend.kind, backend.description)
            controller.start()
            app.state.controller = controller
            app.state.backend = backend
            app.state.runs = RunManager(controller, settings.runs.folder_path)
            app.state.world = WorldService(controller)
            controller.pose_status = app.state.world.tracker.status
            runs = lambda: app.state.runs  # noqa: E731
            app.state.scene = await asyncio.to_thread(start_scene, settings, controller, runs)
            try:
                yield
            finally:
                if app.state.scene is not None:
                    await asyncio.to_thread(app.state.scene.stop)
                await asyncio.to_thread(app.state.runs.close)
                app.state.world.close()
                await asyncio.to_thread(controller.stop)

    app = FastAPI(
        title="deltadash",
        description="Teleoperation API of a Delta robot. SI units (m, rad, s), base frame.",
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.lease = Lease()
    _install_error_handlers(app)
    app.include_router(robot.router, prefix="/api")
    app.include_router(telemetry.router, prefix="/api")
    app.include_router(runs.router, prefix="/api")
    app.include_router(mav.router, prefix="/api")
    app.include_router(dashboard.router)  # /api/info, sinusoid check, /vendor for static/
    if (STATIC_DIR / "index.html").exists():
        app.mount("/", StaticFiles(directory=STATIC_DIR, html=True), name="static")
    return app

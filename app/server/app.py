"""The FastAPI application: its lifespan owns the bus and the control loop.

Startup opens the configured backend (simulator, emulator or real servos) and starts the
controller's thread (and makes the pool of program-check worker processes, which start on
the first check); shutdown kills those workers, stops motion, relaxes the servos per
config and closes the bus. The workers are killed first of all, as the stop begins
(``begin_shutdown``, called by app/server/serving.py before uvicorn waits for the
requests in flight), so a check in flight never holds the server. Errors map to HTTP
codes in one place, app/server/errors.py.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import sys
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from fastapi import Depends, FastAPI
from fastapi.staticfiles import StaticFiles
from fastapi_offline import FastAPIOffline

from app.calibration.probe import Touch, twin_probe
from app.calibration.procedure import CalibrationManager, per_leg, pose_input
from app.config import Settings
from app.control.authority import Authority
from app.foxglove import start_foxglove
from app.origins import OriginPolicy
from app.programs.workers import ProgramWorkers
from app.runs.manager import RunManager
from app.scene import start_scene
from app.server.api import (
    calibration,
    compare,
    contact,
    dashboard,
    mav,
    programs,
    robot,
    ros2,
    runs,
    servos,
    telemetry,
    tuning,
    workspace,
)
from app.server.api.deps import require_read_token
from app.server.backends import open_backend
from app.server.bodies import StrictJSON
from app.server.errors import install_error_handlers
from app.server.estop import EstopFirst, EstopReceipts
from app.server.limits import RequestLimits
from app.server.origins import OriginCheck
from app.server.queries import WorkspaceQueries
from app.server.robot_link import open_robot
from app.server.ros2_arming import RosGoalArming
from app.server.world_client import WorldClient
from app.static_files import static_dir
from app.tuning.procedure import TuningManager
from kinematics import PerLegRotaryDelta, RotaryDelta

log = logging.getLogger(__name__)
GIL_SWITCH_S = 2.5e-4
STATIC_DIR = static_dir()


def begin_shutdown(app: FastAPI) -> None:
    """The first step of stopping, before the server waits for the requests in flight
    (app/server/serving.py): kill the program-check workers, so a check in flight (up to
    programs.check_timeout_s) answers 503 now instead of holding the stop, and no new one
    starts. Blocks for milliseconds; safe before startup or twice (the lifespan's end
    closes them again)."""
    for name in ("program_workers", "queries"):  # workspace queries' workers too
        workers = getattr(app.state, name, None)
        if workers is not None:
            workers.close()


def _twin_probe(settings: Settings, controller: Any) -> Touch | None:
    """The simulated robot's probe (touches from its true model), None on real hardware."""
    drawing = settings.robot.symmetric()  # the twin is built around it (backends._twin)
    if settings.hardware.backend != "sim" or not isinstance(drawing, RotaryDelta):
        return None
    truth = settings.hardware.sim.true_robot(drawing) or PerLegRotaryDelta.from_symmetric(drawing)
    return twin_probe(
        truth, lambda: per_leg(controller.robot), lambda: controller.joint_offsets_rad
    )


def create_app(
    settings: Settings, backend_opener: Callable = open_backend, config_path: Path | None = None
) -> FastAPI:
    """The app for ``settings``; ``backend_opener`` is swappable for tests; ``config_path``:
    the TOML file the settings came from, where an applied calibration is written."""

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
        with open_robot(settings, backend_opener) as opened:
            controller = opened.client  # the loop, in this process or in a robot node
            # the robot's sections (robot, joints, limits, ...) are the node's own config
            live = app.state.settings = controller.settings
            app.state.controller = controller
            app.state.node = opened.node  # the robot node, when it runs in this process
            app.state.robot_child = opened.child  # the embedded node's process, if any
            backend = opened.backend
            app.state.estop_receipts = EstopReceipts(controller)  # /api/estop's presses
            # the page's other e-stop path is the robot node's own listener: its port
            node_listener = opened.node.estop_listener if opened.node is not None else None
            app.state.estop_listener = node_listener  # (a node elsewhere: its info says)
            app.state.backend = backend
            app.state.runs = RunManager(controller, settings.runs.folder_path)
            # the node's ROS goal input: armed for one operator's lease (app/server/ros2_arming.py)
            app.state.ros2_arming = RosGoalArming(app.state.authority, controller)
            # hold-in-world: the pose inputs and the hold run beside the loop, in the node
            app.state.world = WorldClient(controller)
            # program checks and dry runs in worker processes (started on the first one)
            app.state.program_workers = ProgramWorkers(
                live, programs.CONCURRENT_CHECKS, settings.programs.check_timeout_s
            )
            # workspace queries (nearest point, sections) too: no request costs the loop
            app.state.queries = WorkspaceQueries(live)
            # one mover at a time: a procedure claims controller.owner while it runs (every
            # motion command asks it: app/control/owner.py), and starts only when the owner
            # says nothing holds the robot (the run manager answers it for its runs)
            app.state.calibration = CalibrationManager(
                controller,
                settings.runs.folder_path / "calibration",
                config_path=config_path,
                probe=_twin_probe(live, controller),
                plates=live.hardware.sim.build_plates() if live.hardware.backend == "sim" else (),
                pose_measure=pose_input(app.state.world.platform),
            )
            app.state.tuning = TuningManager(
                controller,
                app.state.runs,
                settings.runs.folder_path / "tuning",
                config_path=config_path,
            )
            runs = lambda: app.state.runs  # noqa: E731
            app.state.scene = await asyncio.to_thread(
                start_scene, live, controller, runs, app.state.authority
            )
            app.state.foxglove = None  # the Foxglove live server, when enabled
            try:
                app.state.foxglove = await asyncio.to_thread(start_foxglove, live, controller, runs)
                yield
            finally:
                if app.state.foxglove is not None:
                    await asyncio.to_thread(app.state.foxglove.stop)
                if app.state.scene is not None:
                    await asyncio.to_thread(app.state.scene.stop)
                await asyncio.to_thread(app.state.program_workers.close)
                await asyncio.to_thread(app.state.queries.close)
                await asyncio.to_thread(app.state.tuning.close)
                await asyncio.to_thread(app.state.calibration.close)
                await asyncio.to_thread(app.state.runs.close)
                await asyncio.to_thread(app.state.ros2_arming.close)
                app.state.world.close()

    app = FastAPIOffline(  # /docs and /redoc from local assets: they work with no internet
        title="deltadash",
        description="Teleoperation API of a Delta robot. SI units (m, rad, s), base frame.",
        lifespan=lifespan,
    )
    app.state.settings = settings
    # one authority for motion: the HTTP routes and the 3D scene check the same lease
    app.state.authority = Authority(settings.server.token, settings.server.lease_timeout_s)
    install_error_handlers(app)
    app.add_middleware(StrictJSON)  # JSON bodies read strictly, once within the size limit
    app.add_middleware(RequestLimits, settings=settings)  # before any body is read
    # other sites' pages and DNS rebinding: refused before the token, a body or a route
    app.add_middleware(OriginCheck, policy=OriginPolicy.from_settings(settings.server))
    app.add_middleware(EstopFirst)  # outermost: an e-stop is latched before anything else
    reads = [Depends(require_read_token)]  # the token on reads too, beyond loopback
    app.include_router(robot.router, prefix="/api", dependencies=reads)
    app.include_router(telemetry.router, prefix="/api", dependencies=reads)
    app.include_router(compare.router, prefix="/api", dependencies=reads)  # before runs
    app.include_router(runs.router, prefix="/api", dependencies=reads)
    app.include_router(mav.router, prefix="/api", dependencies=reads)
    app.include_router(workspace.router, prefix="/api", dependencies=reads)
    app.include_router(programs.router, prefix="/api", dependencies=reads)
    app.include_router(calibration.router, prefix="/api", dependencies=reads)
    app.include_router(tuning.router, prefix="/api", dependencies=reads)
    app.include_router(servos.router, prefix="/api", dependencies=reads)
    app.include_router(ros2.router, prefix="/api", dependencies=reads)
    app.include_router(contact.router, prefix="/api", dependencies=reads)
    # /api/info (the page asks it whether to prompt for the token), sinusoid check, /vendor
    app.include_router(dashboard.router)
    if (STATIC_DIR / "index.html").exists():
        app.mount("/", StaticFiles(directory=STATIC_DIR, html=True), name="static")
    return app

"""Typed dependencies: what routes read from ``app.state`` (controller, runs, calibration,
world, scene, settings, authority, program workers), the token check and the control lease
(app/control/authority.py). Only this module reads ``app.state``; routes declare what they need as
``Annotated[..., Depends(...)]`` aliases."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Header, HTTPException, WebSocket
from starlette.requests import HTTPConnection

from app.calibration.procedure import CalibrationManager
from app.config import Settings
from app.control.authority import Authority, ControlRefused, TokenRequired, is_loopback
from app.link.client import RobotClient
from app.programs.workers import ProgramWorkers
from app.runs.manager import RunManager
from app.scene import Scene
from app.server.estop import EstopReceipts
from app.server.queries import WorkspaceQueries
from app.server.ros2_arming import RosGoalArming
from app.server.world_client import WorldClient
from app.tuning.procedure import TuningManager

READS = ("GET", "HEAD")


def get_controller(connection: HTTPConnection) -> RobotClient:
    """The robot (its loop, here or in a robot node: app/link/client.py); 503 when it is
    not running (before startup, after shutdown) or its node is offline."""
    controller: RobotClient = connection.app.state.controller
    if not controller.running:
        if getattr(controller, "offline_for_s", None) is not None:
            raise HTTPException(
                503,
                f"robot offline: no state from the robot node for "
                f"{controller.offline_for_s:.1f} s; reconnecting",
                headers={"Retry-After": "1"},
            )
        raise HTTPException(503, "the control loop is not running")
    return controller


def get_settings(connection: HTTPConnection) -> Settings:
    return connection.app.state.settings


def get_command_wait(connection: HTTPConnection) -> float:
    """How long a command waits for the control loop to run it [s] (then a 503)."""
    return connection.app.state.settings.server.command_timeout_s


def get_runs(connection: HTTPConnection) -> RunManager:
    return connection.app.state.runs


def get_ros2_arming(connection: HTTPConnection) -> RosGoalArming:
    return connection.app.state.ros2_arming


def get_queries(connection: HTTPConnection) -> WorkspaceQueries:
    """The app's workspace queries (worker processes, app/server/queries.py)."""
    return connection.app.state.queries


def get_program_workers(connection: HTTPConnection) -> ProgramWorkers:
    """The worker processes that check programs (created by the lifespan)."""
    return connection.app.state.program_workers


def get_calibration(connection: HTTPConnection) -> CalibrationManager:
    return connection.app.state.calibration


def get_tuning(connection: HTTPConnection) -> TuningManager:
    return connection.app.state.tuning


def get_world(connection: HTTPConnection) -> WorldClient:
    return connection.app.state.world


def get_scene(connection: HTTPConnection) -> Scene | None:
    """The 3D scene, None when the config turns it off."""
    return getattr(connection.app.state, "scene", None)


def get_estop_port(connection: HTTPConnection) -> int | None:
    """The robot node's e-stop listener's port (app/robot/estop.py), None when it runs none:
    a node in this process's own, else what the node said when its link was last taken
    (a node started again may have another)."""
    listener = getattr(connection.app.state, "estop_listener", None)
    if listener is not None:
        return listener.port
    controller = getattr(connection.app.state, "controller", None)
    return None if controller is None else controller.info.get("estop_port")


def get_estop_receipts(connection: HTTPConnection) -> EstopReceipts:
    """The e-stop presses' record, which every e-stop path goes through (app/server/estop.py)."""
    return connection.app.state.estop_receipts


def get_authority(connection: HTTPConnection) -> Authority:
    return connection.app.state.authority


def bearer(authorization: str | None) -> str | None:
    """The token in ``Authorization: Bearer <token>``; None for anything else, a bare token
    included (it would teach clients a form other servers and proxies do not treat as a
    credential)."""
    scheme, _, value = (authorization or "").strip().partition(" ")
    return (value.strip() or None) if scheme.lower() == "bearer" else None


def require_token(
    authority: Annotated[Authority, Depends(get_authority)],
    authorization: Annotated[str | None, Header()] = None,
) -> None:
    """Control requests carry ``Authorization: Bearer <token>`` when a token is set."""
    try:
        authority.require_token(bearer(authorization))
    except TokenRequired as exc:
        raise HTTPException(401, str(exc)) from None


def reads_need_token(settings: Settings) -> bool:
    """A token is set and the server is reachable from other machines (not loopback)."""
    return settings.server.token is not None and not is_loopback(settings.server.host)


def require_read_token(
    connection: HTTPConnection,
    authority: Annotated[Authority, Depends(get_authority)],
    settings: Annotated[Settings, Depends(get_settings)],
) -> None:
    """GETs need the token too where other machines can reach the server (see
    ``reads_need_token``). Commands check it themselves (e-stop is open to anyone);
    WebSockets check it on connecting (``websocket_token_ok``)."""
    reading = connection.scope["type"] == "http" and connection.scope["method"] in READS
    if not reading or not reads_need_token(settings):
        return
    try:
        authority.require_token(bearer(connection.headers.get("authorization")))
    except TokenRequired as exc:
        raise HTTPException(401, str(exc)) from None


def websocket_token_ok(websocket: WebSocket) -> bool:
    """``?token=`` (browsers cannot set headers on a WebSocket) or a Bearer header."""
    supplied = websocket.query_params.get("token") or bearer(websocket.headers.get("authorization"))
    return websocket.app.state.authority.token_ok(supplied)


def require_control(
    authority: Annotated[Authority, Depends(get_authority)],
    _: Annotated[None, Depends(require_token)],
    x_lease: Annotated[str | None, Header(description="lease_id from POST /api/lease")] = None,
) -> str:
    """The one check for commands that move the robot or change its power: the token, then
    the lease id in ``X-Lease`` (renewed). Returns the holder's display name."""
    try:
        return authority.check(x_lease)
    except ControlRefused as exc:
        raise HTTPException(409, str(exc)) from None


ControllerDep = Annotated[RobotClient, Depends(get_controller)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
CommandWait = Annotated[float, Depends(get_command_wait)]
RunsDep = Annotated[RunManager, Depends(get_runs)]
Ros2ArmingDep = Annotated[RosGoalArming, Depends(get_ros2_arming)]
ProgramWorkersDep = Annotated[ProgramWorkers, Depends(get_program_workers)]
QueriesDep = Annotated[WorkspaceQueries, Depends(get_queries)]
CalibrationDep = Annotated[CalibrationManager, Depends(get_calibration)]
TuningDep = Annotated[TuningManager, Depends(get_tuning)]
WorldDep = Annotated[WorldClient, Depends(get_world)]
SceneDep = Annotated[Scene | None, Depends(get_scene)]
AuthorityDep = Annotated[Authority, Depends(get_authority)]
EstopPortDep = Annotated[int | None, Depends(get_estop_port)]
EstopReceiptsDep = Annotated[EstopReceipts, Depends(get_estop_receipts)]
ControlClient = Annotated[str, Depends(require_control)]
TokenChecked = Annotated[None, Depends(require_token)]

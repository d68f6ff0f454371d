"""Errors to HTTP: only the project's own exception types become operator errors.

A bad goal is 422 (with the nearest reachable point when known), a robot that cannot move
now is 409, a bus or control loop that does not answer is 503, a missing token 401. Any
other exception is a bug: a 500 with a generic body, its traceback in the log, never
dressed as something the operator did.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.control.errors import GoalRejected, MotionRefused
from app.link.protocol import RemoteError, RobotOffline
from app.programs.workers import WorkerError
from hardware.errors import BusError
from kinematics import PoseError

log = logging.getLogger(__name__)
INTERNAL_ERROR = "internal server error (a bug): see the server log"


class ErrorBody(BaseModel):
    """Every error response: what went wrong, in words."""

    model_config = ConfigDict(extra="forbid")
    detail: str
    nearest_m: list[float | None] | None = Field(
        None,
        description="422 for a goal the gate refuses (outside the workspace, beyond a joint "
        "limit, near a singularity): a point near it that the gate accepts [m]",
    )


class PlanningTimeout(TimeoutError):
    """Planning a run took longer than its bound: the run is not started (503, this text)."""


def _response(description: str) -> dict[str, Any]:
    return {"model": ErrorBody, "description": description}


UNAUTHORISED = {401: _response("missing or wrong token (Authorization: Bearer <token>)")}
NOT_FOUND = {404: _response("no such run or file")}
CONFLICT = {409: _response("the robot cannot move now, or another client holds control")}
INVALID = {422: _response("invalid body or goal; nearest_m when a point is out of reach")}
UNAVAILABLE = {503: _response("the servo bus or the control loop did not answer")}
TOO_LARGE = {413: _response("request body over server.max_body_bytes (refused unread)")}
CONTROL = {**UNAUTHORISED, **CONFLICT, **TOO_LARGE, **INVALID, **UNAVAILABLE}
"""What a control route (token, lease, command to the loop) can answer besides 200."""


def _error(status: int, detail: str, **extra: Any) -> JSONResponse:
    return JSONResponse({"detail": detail, **extra}, status_code=status)


FIELD_SHAPED = ("/api/programs/",)
"""Routes whose 422 bodies carry ``line``, ``word`` and ``violations`` (the programs' own
error shape, docs/gcode.md): a body refused before any program is read answers them too,
``line`` and ``word`` null, ``violations`` one ``{field, reason}`` per problem."""


def _problems(exc: RequestValidationError) -> list[tuple[str, str]]:
    """(field, reason) per error: ('position_m.1', 'Input should be a finite number'), the
    field dotted, 'body' for the body as a whole, 'query.body' for a query parameter;
    never echoes raw input. Only a leading 'body' (where a JSON body's field came from)
    is left out, never a field's own name."""
    problems = []
    for error in exc.errors():
        loc = list(error["loc"])
        if loc and loc[0] == "body":
            loc = loc[1:]
        problems.append((".".join(str(p) for p in loc) or "body", error["msg"]))
    return problems


def invalid_body(path: str, problems: list[tuple[str, str]]) -> JSONResponse:
    """The 422 of a request refused before its route ran: ``detail`` is
    ``"field: reason"`` per problem, joined by ``"; "``; on the programs routes
    (FIELD_SHAPED) also ``line`` and ``word`` (null: no program was read) and
    ``violations``: ``[{"field", "reason"}]``."""
    detail = "; ".join(f"{field}: {reason}" for field, reason in problems)
    if not path.startswith(FIELD_SHAPED):
        return _error(422, detail)
    violations = [{"field": field, "reason": reason} for field, reason in problems]
    return _error(422, detail, line=None, word=None, violations=violations)


async def _offer(request: Request, exc: GoalRejected) -> tuple[str, dict[str, Any]]:
    """The 422's words and ``nearest_m``: for a refused goal (``exc.goal``) a point the gate
    accepts at the goal's wrist angle (sections.nearest, workspace, joint limits and
    margins; tens of ms to seconds, in a worker process: app/server/queries.py), else, and
    when every worker is busy, the exception's own ``nearest`` if any."""
    controller = getattr(request.app.state, "controller", None)
    queries = getattr(request.app.state, "queries", None)
    if exc.goal is None or controller is None or queries is None:
        return _own_offer(exc)
    try:  # in a worker process (app/server/queries.py): the loop's process only waits
        point = await asyncio.to_thread(queries.nearest, controller.gate, exc.goal, exc.phi)
    except (WorkerError, ValueError):  # busy, or no accepted point: the gate's own offer
        return _own_offer(exc)
    mm = ", ".join(f"{v:.4f}" for v in point)
    return f"{exc.reason}; nearest reachable point [{mm}] m", {"nearest_m": point.tolist()}


def _own_offer(exc: GoalRejected) -> tuple[str, dict[str, Any]]:
    """The refusal's own words and ``nearest`` (the gate's workspace projection, if any)."""
    nearest = None if exc.nearest is None else [float(v) for v in exc.nearest]
    return str(exc), {"nearest_m": nearest}


def install_error_handlers(app: FastAPI) -> None:
    """Map the project's exceptions to 401/409/422/503; anything else is a logged 500."""

    @app.exception_handler(RequestValidationError)
    async def invalid_request(request: Request, exc: RequestValidationError) -> JSONResponse:
        return invalid_body(request.scope["path"], _problems(exc))

    @app.exception_handler(GoalRejected)
    async def goal_rejected(request: Request, exc: GoalRejected) -> JSONResponse:
        detail, extra = await _offer(request, exc)
        return _error(422, detail, **extra)

    @app.exception_handler(PoseError)
    async def pose_error(_: Request, exc: PoseError) -> JSONResponse:
        return _error(422, str(exc))

    @app.exception_handler(MotionRefused)
    async def motion_refused(_: Request, exc: MotionRefused) -> JSONResponse:
        return _error(409, str(exc))

    @app.exception_handler(BusError)
    async def bus_error(_: Request, exc: BusError) -> JSONResponse:
        return _error(503, f"servo bus: {exc}")

    @app.exception_handler(RobotOffline)  # the robot node did not answer
    async def robot_offline(_: Request, exc: RobotOffline) -> JSONResponse:
        return JSONResponse(
            {"detail": f"robot offline: {exc}"}, status_code=503, headers={"Retry-After": "1"}
        )

    @app.exception_handler(RemoteError)  # the robot node failed on a command (a bug there)
    async def remote_error(_: Request, exc: RemoteError) -> JSONResponse:
        return _error(503, f"robot node: {exc}")

    @app.exception_handler(WorkerError)  # a workspace query refused (busy) or not answered
    async def query_unavailable(_: Request, exc: WorkerError) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=503, headers={"Retry-After": "1"})

    @app.exception_handler(TimeoutError)  # a command the control loop did not answer in time
    async def timeout(_: Request, exc: TimeoutError) -> JSONResponse:
        if isinstance(exc, PlanningTimeout):
            return _error(503, str(exc))
        return _error(503, "the control loop did not answer in time")

    app.add_middleware(BugsAre500)


STOPPING = "the server is stopping: the request was not completed; try again once it is back"
STOPPING_RETRY_S = 5  # Retry-After of a request the stopping server abandoned


class BugsAre500:
    """ASGI middleware: an exception no handler took is logged with its traceback and
    answered 500 with a generic body (Starlette's own last resort would re-raise it to the
    server, which logs it a second time, and answer in plain text).

    A request still waiting when the server stops for good (a second Ctrl-C: uvicorn stops
    waiting for requests in flight and the event loop cancels their tasks) is no bug:
    answered 503 with Retry-After (uvicorn's own answer to the cancellation would be a
    500), then the cancellation goes on."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def tracked_send(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, receive, tracked_send)
        except asyncio.CancelledError:
            if not started:
                log.warning(
                    "%s %s abandoned: the server is stopping", scope["method"], scope["path"]
                )
                headers = {"Retry-After": str(STOPPING_RETRY_S)}
                await JSONResponse({"detail": STOPPING}, 503, headers)(scope, receive, send)
            raise
        except Exception:
            log.exception("%s %s failed (a bug)", scope["method"], scope["path"])
            if started:  # too late for a status code; let the server close the connection
                raise
            await _error(500, INTERNAL_ERROR)(scope, receive, send)

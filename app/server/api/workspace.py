"""Workspace resource: planar sections of the gate's workspace and the nearest reachable
point to a goal, for the page's 2D view (app/server/sections.py)."""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Query

from app.fields import REACH_M
from app.server import sections
from app.server.api.deps import ControllerDep, QueriesDep
from app.server.api.responses import NearestOut, WorkspaceSectionOut
from app.server.errors import INVALID, UNAVAILABLE

router = APIRouter(prefix="/workspace", tags=["workspace"])
Coordinate = Annotated[
    float, Query(ge=-REACH_M, le=REACH_M, allow_inf_nan=False, description="[m], |value| <= 1")
]
WristAngle = Annotated[
    float,
    Query(
        allow_inf_nan=False,
        description="the wrist angle of the tips [rad], within the wrist's limits (0 without "
        "a wrist): with a tool off the wrist's axis the accepted region moves as it turns",
    ),
]


@router.get("/section", response_model=WorkspaceSectionOut, responses={**INVALID, **UNAVAILABLE})
def get_section(
    controller: ControllerDep,
    queries: QueriesDep,
    plane: Annotated[
        sections.Plane, Query(description="xy: top view at z = at_m; xz: at y = at_m; yz: at x")
    ],
    at_m: Coordinate,
    phi_rad: WristAngle = 0.0,
) -> dict[str, Any]:
    """Where the gate accepts a goal (a tool tip at ``phi_rad``) on a plane: a grid of cell
    centres, one string per row (v), '1' where accepted (workspace with the gate's margin
    and ceiling, joint limits and singularity margin on the knee-out branch). The level is
    rounded to 1 mm and phi to 1 deg (``at_m`` and ``phi_rad`` in the answer are the ones
    used); a phi outside the wrist's limits is a 422 naming ``phi_rad``. Computed in a
    worker process (app/server/queries.py): 503 with Retry-After while every worker is
    busy."""
    phi = controller.gate.check_phi(phi_rad)
    cut = queries.section(controller.gate, plane, at_m, phi)  # in a worker process
    u_axis, v_axis, level_axis = ("xyz"[k] for k in sections.AXES[plane])
    return {
        "plane": plane,
        "at_m": cut.level_m,
        "phi_rad": cut.phi_rad,
        "axes": [u_axis, v_axis, level_axis],
        "u_m": cut.u_m.tolist(),
        "v_m": cut.v_m.tolist(),
        "reachable": ["".join("1" if c else "0" for c in row) for row in cut.reachable.tolist()],
        "margin_m": controller.gate.margin_m,
        "z_max_m": controller.gate.z_max_m,
    }


@router.get("/nearest", response_model=NearestOut, responses={**INVALID, **UNAVAILABLE})
def get_nearest(
    controller: ControllerDep,
    queries: QueriesDep,
    x_m: Coordinate,
    y_m: Coordinate,
    z_m: Coordinate,
    phi_rad: WristAngle = 0.0,
) -> dict[str, Any]:
    """Whether the gate accepts a point (a tool tip at ``phi_rad``) as a goal and, if not,
    a nearby point it accepts at that angle: the workspace's nearest point (the 422's
    ``nearest_m``) when that passes the joint limits too, else the accepted point nearest it
    on the way to the workspace's centre (app/server/sections.py ``nearest``). Computed in
    a worker process (app/server/queries.py): 503 with Retry-After while every worker is
    busy."""
    point = np.array([x_m, y_m, z_m])
    nearest = queries.nearest(controller.gate, point, controller.gate.check_phi(phi_rad))
    return {
        "position_m": point.tolist(),
        "inside": bool(np.array_equal(nearest, point)),
        "nearest_m": [float(v) for v in nearest],
        "distance_m": float(np.linalg.norm(nearest - point)),
    }

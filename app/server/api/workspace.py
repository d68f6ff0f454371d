"""Workspace resource: planar sections of the gate's workspace and the nearest reachable
point to a goal, for the page's 2D view (app/server/sections.py)."""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Query

from app.server import sections
from app.server.api.deps import ControllerDep
from app.server.api.models import REACH_M
from app.server.api.responses import NearestOut, WorkspaceSectionOut
from app.server.errors import INVALID, UNAVAILABLE

router = APIRouter(prefix="/workspace", tags=["workspace"])
Coordinate = Annotated[
    float, Query(ge=-REACH_M, le=REACH_M, allow_inf_nan=False, description="[m], |value| <= 1")
]


@router.get("/section", response_model=WorkspaceSectionOut, responses={**INVALID, **UNAVAILABLE})
def get_section(
    controller: ControllerDep,
    plane: Annotated[
        sections.Plane, Query(description="xy: top view at z = at_m; xz: at y = at_m; yz: at x")
    ],
    at_m: Coordinate,
) -> dict[str, Any]:
    """Where the gate accepts a goal on a plane: a grid of cell centres, one string per row
    (v), '1' where accepted. The gate's margin and ceiling apply; the level is rounded to
    1 mm (``at_m`` in the answer is the one used)."""
    cut = sections.section(controller.gate, plane, at_m)
    u_axis, v_axis, level_axis = ("xyz"[k] for k in sections.AXES[plane])
    return {
        "plane": plane,
        "at_m": cut.level_m,
        "axes": [u_axis, v_axis, level_axis],
        "u_m": cut.u_m.tolist(),
        "v_m": cut.v_m.tolist(),
        "reachable": ["".join("1" if c else "0" for c in row) for row in cut.reachable.tolist()],
        "margin_m": controller.gate.margin_m,
        "z_max_m": controller.gate.z_max_m,
    }


@router.get("/nearest", response_model=NearestOut, responses={**INVALID, **UNAVAILABLE})
def get_nearest(
    controller: ControllerDep, x_m: Coordinate, y_m: Coordinate, z_m: Coordinate
) -> dict[str, Any]:
    """Whether a point is inside the gate's workspace and, if not, the nearest point that is
    (the same projection the 422 of POST /api/goal answers as ``nearest_m``)."""
    point = np.array([x_m, y_m, z_m])
    inside = controller.gate.inside(point)
    nearest = point if inside else controller.gate.nearest(point)
    return {
        "position_m": point.tolist(),
        "inside": inside,
        "nearest_m": [float(v) for v in nearest],
        "distance_m": float(np.linalg.norm(nearest - point)),
    }

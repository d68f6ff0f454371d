"""JSON number fields of the request bodies (pydantic; SI units, base frame): strict
finite numbers, 3-vectors and the reach bound. The API's bodies (app/server/api/models.py)
and the run types' parameters (app/runs/types.py) both take them from here, below either.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

# strict: a number is a JSON number, never a string ("0.1") or a boolean
Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]
Vector3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
REACH_M = 1.0
"""No Delta this app drives reaches this far [m]; a path's points and amplitudes beyond it
are refused by the model, the rest by the feasibility check against the robot's own reach."""
Reach = Annotated[float, Field(ge=-REACH_M, le=REACH_M, allow_inf_nan=False, strict=True)]
ReachVector3 = Annotated[list[Reach], Field(min_length=3, max_length=3)]

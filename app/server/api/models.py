"""Request and response bodies of the API (SI units, base frame)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from app.fields import Finite, Vector3


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


PHI_DESCRIPTION = (
    "wrist angle [rad] of the tool about the platform's z; 0 (the default) is the only one "
    "without a [wrist] section"
)


class GoalRequest(_Body):
    position_m: Vector3 = Field(
        description="tool tip goal [m], 3 finite numbers (the platform centre without [tool])"
    )
    phi_rad: Finite = Field(0.0, description=PHI_DESCRIPTION)
    frame: Literal["base"] = Field("base", description="only the base frame for now")


class JogRequest(_Body):
    """Exactly one of: a bounded step (scripts), or a held jog's velocity (hold-to-move)."""

    delta_m: Vector3 | None = Field(
        None, description="relative step [m] from what the loop commands now; clamped"
    )
    velocity_m_s: Vector3 | None = Field(
        None,
        description="held jog [m/s]: moves only while repeated (every ~50 ms); stops "
        "jog.hold_timeout_s (0.15 s) after the last; zero stops at once; capped at the jog speed",
    )

    @model_validator(mode="after")
    def _one_of(self) -> JogRequest:
        if (self.delta_m is None) == (self.velocity_m_s is None):
            raise ValueError("give exactly one of delta_m or velocity_m_s")
        return self


class MoveRequest(_Body):
    position_m: Vector3 | None = Field(None, description="Cartesian target of the tool tip [m]")
    phi_rad: Finite = Field(0.0, description=PHI_DESCRIPTION)
    joints_rad: Vector3 | None = Field(None, description="joint target [rad]")
    space: Literal["cartesian", "joint"] = Field("cartesian", description="path shape")
    duration_s: Annotated[float, Field(gt=0, le=60, allow_inf_nan=False)] | None = Field(
        None, description="at least this long [s]; default: as fast as the limits allow"
    )


class TorqueRequest(_Body):
    enabled: bool


class LeaseRequest(_Body):
    client: Annotated[str, Field(min_length=1, max_length=64)] = Field(
        description="a display name for the holder (shown by GET /api/lease; not a credential)"
    )
    take_over: bool = Field(False, description="take control from the current holder")


class Accepted(BaseModel):
    accepted: bool = True
    result: object = None

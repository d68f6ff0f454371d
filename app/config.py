"""Settings of ``deltadash serve``: one TOML file, environment variables, CLI flags.

Precedence, highest first: command-line flags, ``DELTADASH_<SECTION>__<KEY>`` environment
variables, the TOML file given with ``--config``, the defaults below. Every field is
documented; a bad value fails at start with its dotted name and the reason.

Example file::

    [robot]
    type = "rotary"
    L = 0.1558
    l = 0.2430
    R = 0.0844
    r = 0.038

    [robot.legs]                          # optional: each leg its own (a geometry calibration)
    lower_link_m = [0.2438, 0.2426, 0.2431]

    [tool]
    offset_m = [0.0, 0.0, -0.05]

    [hardware]
    backend = "dynamixel"
    port = "/dev/ttyUSB0"
    baud = 4000000

    [[hardware.joints]]
    servo_id = 1
    zero_offset_ticks = 2048
    direction = 1

    [hardware.sim]                        # the twin built wrong on purpose (calibration)
    true_joint_offsets_rad = [0.05, -0.03, 0.02]
    true_lower_link_m = [0.2440, 0.2425, 0.2430]
    measurement_noise_m = 0.0003
    [wrist]            # optional: a fourth servo turning the tool about the platform's z
    enabled = true
    servo_id = 4
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from contextvars import ContextVar
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    FiniteFloat,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_settings import (
    BaseSettings,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
    TomlConfigSettingsSource,
)

from hardware.bus import PositionGains
from hardware.calibration import JointCalibration
from hardware.dynamixel.control_table import Reg, current_to_ampere
from kinematics import DeltaError, LinearDelta, PerLegRotaryDelta, RotaryDelta, Tool

if TYPE_CHECKING:
    from hardware.sim.surfaces import Plate

# The file is chosen at run time (``deltadash serve --config FILE``) while the sources are
# built inside ``Settings()``; a context variable hands the path over without a global.
_TOML_PATH: ContextVar[Path | None] = ContextVar("deltadash_config_path", default=None)


class _Section(BaseModel):
    """One ``[section]`` of the TOML file: unknown keys are errors, values are frozen."""

    model_config = ConfigDict(extra="forbid", frozen=True)


Triple = tuple[FiniteFloat, FiniteFloat, FiniteFloat]
#: The XM430-W210's factory Current Limit (38) [A]: 1193 units of 2.69 mA = 3.209 A.
XM430_CURRENT_LIMIT_A = current_to_ampere(Reg.CURRENT_LIMIT.value.default)

# per-leg fields of [robot.legs] and the PerLegRotaryDelta field each one sets
_LEGS = {
    "upper_link_m": "L",
    "lower_link_m": "l",
    "base_radius_m": "R",
    "platform_radius_m": "r",
    "base_angles_rad": "angles_rad",
}


class LegSettings(_Section):
    """``[robot.legs]``: each leg its own geometry (a rotary Delta's, leg order), as a
    geometry calibration found it (POST /api/calibration/{run_id}/apply writes it).

    A field left out is [robot]'s value for every leg. Distinct names, not L and l:
    environment variables ignore case. Joint offsets are not here: they are the joints'
    zero offsets (``[[hardware.joints]]``).
    """

    upper_link_m: Triple | None = Field(None, description="L per leg [m] (robot.L)")
    lower_link_m: Triple | None = Field(None, description="l per leg [m] (robot.l)")
    base_radius_m: Triple | None = Field(None, description="R per leg [m] (robot.R)")
    platform_radius_m: Triple | None = Field(None, description="r per leg [m] (robot.r)")
    base_angles_rad: Triple | None = Field(
        None, description="direction of each leg's base position about z [rad] (0, 120, 240 deg)"
    )

    @classmethod
    def of(cls, robot: PerLegRotaryDelta) -> LegSettings:
        """The section that describes ``robot``'s legs (its joint offsets are not kept)."""
        return cls(**{key: getattr(robot, name) for key, name in _LEGS.items()})

    def values(self) -> dict[str, Triple]:
        """The PerLegRotaryDelta fields given here (L, l, R, r, angles_rad), three values
        each."""
        given = {_LEGS[key]: value for key, value in self.model_dump().items()}
        return {name: value for name, value in given.items() if value is not None}


class RobotSettings(_Section):
    """Geometry [m]; defaults are the thesis robot (eq. 4.11).

    With ``[robot.legs]`` the controller's model is the per-leg one it describes
    (``build``); L, l, R, r stay the drawing's values (``symmetric``), which the simulated
    robot's ``[hardware.sim]`` true values default to.
    """

    type: Literal["rotary", "linear"] = Field("rotary", description="rotary or linear Delta")
    L: float = Field(0.1558, description="upper link length [m] (rotary)")
    l: float = Field(0.2430, description="parallelogram length [m]")
    R: float = Field(0.0844, description="base radius to the motor axis / rail [m]")
    r: float = Field(0.038, description="platform radius [m]")
    incline_rad: float = Field(math.pi / 2, description="rail angle above the base [rad] (linear)")
    legs: LegSettings | None = Field(
        None,
        description="per-leg geometry of a rotary Delta (a geometry calibration writes it); "
        "none: every leg is L, l, R, r",
    )

    @model_validator(mode="after")
    def _buildable(self) -> RobotSettings:
        try:
            self.symmetric()
        except DeltaError as exc:
            raise ValueError(str(exc)) from exc
        return self  # the legs are checked by Settings, which names their field in full

    def symmetric(self) -> RotaryDelta | LinearDelta:
        """The robot of L, l, R, r (every leg alike): the drawing, without ``legs``."""
        if self.type == "linear":
            return LinearDelta(l=self.l, R=self.R, r=self.r, incline=self.incline_rad)
        return RotaryDelta(L=self.L, l=self.l, R=self.R, r=self.r)

    def build(self) -> RotaryDelta | PerLegRotaryDelta | LinearDelta:
        """The kinematics object these settings describe: the per-leg robot of ``legs``
        when given, else the symmetric one."""
        robot = self.symmetric()
        if self.legs is None or not isinstance(robot, RotaryDelta):
            return robot
        return PerLegRotaryDelta.from_symmetric(robot, **self.legs.values())


class GainSettings(_Section):
    """A servo's position gains in the XM430's register units (docs/tuning.md)."""

    p: int = Field(800, ge=0, le=16383, description="Position P Gain (KpP = p / 128)")
    i: int = Field(0, ge=0, le=16383, description="Position I Gain (KiP = i / 65536)")
    d: int = Field(0, ge=0, le=16383, description="Position D Gain (KdP = d / 16)")
    ff1: int = Field(0, ge=0, le=16383, description="Feedforward 1st Gain (velocity, / 4)")
    ff2: int = Field(0, ge=0, le=16383, description="Feedforward 2nd Gain (acceleration, / 4)")

    def position_gains(self) -> PositionGains:
        return PositionGains(self.p, self.i, self.d, self.ff1, self.ff2)


class JointSettings(_Section):
    """Calibration of one joint (see hardware/calibration.py and docs/hardware.md)."""

    servo_id: int = Field(ge=0, le=252, description="Dynamixel id")
    zero_offset_ticks: int = Field(2048, description="raw position at theta = 0 [ticks]")
    direction: Literal[1, -1] = Field(1, description="+1 if ticks grow with theta, else -1")
    min_angle_rad: float = Field(-0.6, description="lowest joint angle [rad] (link up)")
    max_angle_rad: float = Field(
        1.65, description="highest joint angle [rad] (link down; hanging relaxed is ~1.55)"
    )
    gains: GainSettings | None = Field(
        None,
        description="a leg's position gains, written to its servo when the server starts "
        "(POST /api/tuning/{run_id}/apply writes them here); none: the servo's own",
    )

    def calibration(self) -> JointCalibration:
        """This joint's calibration as the buses take it (hardware/calibration.py)."""
        return JointCalibration(
            self.servo_id,
            self.zero_offset_ticks,
            self.direction,
            self.min_angle_rad,
            self.max_angle_rad,
        )


class WristSettings(JointSettings):
    """The optional fourth servo: a wrist turning the tool about the platform's z axis.

    Its angle phi [rad] maps to ticks as a leg's theta does (zero offset, direction); phi
    = 0 is the tool's heading at assembly. It shares the legs' bus (one sync read and one
    sync write for all four servos). Without ``enabled`` the bus has the three legs only.
    """

    enabled: bool = Field(False, description="a wrist servo is fitted (a fourth servo on the bus)")
    servo_id: int = Field(4, ge=0, le=252, description="Dynamixel id of the wrist servo")
    min_angle_rad: float = Field(-3.0, description="lowest wrist angle phi [rad]")
    max_angle_rad: float = Field(3.0, description="highest wrist angle phi [rad]")
    max_speed_rad_s: float = Field(
        5.0, gt=0, description="largest commanded wrist speed [rad/s] (XM430-W210: 8.1 no-load)"
    )

    @model_validator(mode="after")
    def _ordered(self) -> WristSettings:
        if not self.min_angle_rad < self.max_angle_rad:
            raise ValueError("min_angle_rad must be below max_angle_rad")
        if self.max_angle_rad - self.min_angle_rad >= 2 * math.pi:
            raise ValueError("the wrist's range must be less than a turn (one encoder turn)")
        return self


def _default_joints() -> list[JointSettings]:
    return [JointSettings(servo_id=i) for i in (1, 2, 3)]


# per-leg fields of [hardware.sim] and the PerLegRotaryDelta field each one sets
_TRUE_LEGS = {
    "true_upper_link_m": "L",
    "true_lower_link_m": "l",
    "true_base_radius_m": "R",
    "true_platform_radius_m": "r",
}


class PlateSettings(_Section):
    """``[[hardware.sim.plates]]``: a plate the twin's tool tip can touch (hardware/sim/
    surfaces.py ``Plate``), fixed in the base frame or (``fixed_in = "world"``) in the
    world; MuJoCo's contact force on it is the truth the force estimate, touch and the
    compliant press are measured against.

    Example::

        [[hardware.sim.plates]]
        point_m = [0.0, 0.0, -0.26]
        normal = [0.0, 0.0, 1.0]
        stiffness_n_m = 10000.0
    """

    point_m: Triple = Field(description="a point of the touched face, base frame [m]")
    normal: Triple = Field(
        (0.0, 0.0, 1.0), description="the face's normal, out of the plate towards the robot"
    )
    half_size_m: tuple[FiniteFloat, FiniteFloat] = Field(
        (0.1, 0.1), description="half the face's extent along its x and y [m]"
    )
    thickness_m: FiniteFloat = Field(
        0.02,
        gt=0,
        le=1.0,
        description="[m]; a penetration past half of it pushes the tip out the far side",
    )
    stiffness_n_m: FiniteFloat = Field(
        1.0e4, gt=0, le=1.0e7, description="contact stiffness: force per penetration [N/m]"
    )
    damping_n_s_m: FiniteFloat = Field(20.0, ge=0, le=1.0e5, description="contact damping [N s/m]")
    friction: FiniteFloat = Field(
        0.5, ge=0, le=5.0, description="Coulomb friction coefficient (0: frictionless)"
    )
    fixed_in: Literal["base", "world"] = Field(
        "base",
        description='"world": a wall fixed in the world, placed by point_m / normal in the '
        "base frame as a hold on the simulated drone starts, then staying put while the "
        "drone drifts (hardware/sim/surfaces.py Plate)",
    )

    @field_validator("normal")
    @classmethod
    def _nonzero(cls, normal: tuple[float, float, float]) -> tuple[float, float, float]:
        if math.hypot(*normal) < 1e-9:
            raise ValueError(f"must not be zero (a direction), got {list(normal)}")
        return normal

    @field_validator("half_size_m")
    @classmethod
    def _positive(cls, half: tuple[float, float]) -> tuple[float, float]:
        if min(half) <= 0.0:
            raise ValueError(f"must be two positive lengths [m], got {list(half)}")
        return half

    def build(self) -> Plate:
        """The twin's plate (hardware.sim.surfaces.Plate)."""
        from hardware.sim.surfaces import Plate  # here: hardware.sim loads MuJoCo

        return Plate(**self.model_dump())


class SimSettings(_Section):
    """``[hardware.sim]``: the twin built wrong on purpose, and its motion capture.

    The controller keeps ``[robot]`` and ``[[hardware.joints]]``; the twin is built from
    these (each leg its own values, leg order), so a calibration has something to find
    (docs/calibration.md). The defaults are the exact twin of [robot]'s L, l, R, r (the
    drawing, never ``[robot.legs]``: what a calibration believes does not change the
    robot that was built).
    """

    true_joint_offsets_rad: Triple = Field(
        (0.0, 0.0, 0.0),
        description="added to each joint's reported angle to give the mechanism's [rad]",
    )
    true_upper_link_m: Triple | None = Field(None, description="true L per leg [m] (robot.L)")
    true_lower_link_m: Triple | None = Field(None, description="true l per leg [m] (robot.l)")
    true_base_radius_m: Triple | None = Field(None, description="true R per leg [m] (robot.R)")
    true_platform_radius_m: Triple | None = Field(None, description="true r per leg [m] (robot.r)")
    measurement_frame_position_m: Triple = Field(
        (0.0, 0.0, 0.0), description="origin of the external measurement's frame, base frame [m]"
    )
    measurement_frame_rpy_rad: Triple = Field(
        (0.0, 0.0, 0.0),
        description="its axes as roll, pitch, yaw about the base axes, Rz Ry Rx [rad]",
    )
    measurement_noise_m: float = Field(
        0.0, ge=0.0, le=0.1, description="white noise per axis of the measurement [m]"
    )
    plates: list[PlateSettings] = Field(
        default_factory=list,
        description="plates the tool tip can touch ([[hardware.sim.plates]]), none by default",
    )

    def build_plates(self) -> tuple[Plate, ...]:
        """The twin's plates, config order."""
        return tuple(p.build() for p in self.plates)

    def true_robot(self, robot: RotaryDelta) -> PerLegRotaryDelta | None:
        """The twin's true geometry around the nominal ``robot``; None for the exact twin.

        Raises:
            ValueError: naming the ``hardware.sim`` field when the legs are no Delta.
        """
        legs = {_TRUE_LEGS[k]: v for k, v in self.model_dump().items() if k in _TRUE_LEGS}
        legs = {k: v for k, v in legs.items() if v is not None}
        if not legs and self.true_joint_offsets_rad == (0.0, 0.0, 0.0):
            return None
        try:
            return PerLegRotaryDelta.from_symmetric(
                robot, joint_offsets_rad=self.true_joint_offsets_rad, **legs
            )
        except DeltaError as exc:
            field = {v: k for k, v in _TRUE_LEGS.items()}.get(str(exc).split("[")[0], "true_*")
            raise ValueError(f"hardware.sim.{field}: {exc}") from exc


MAX_TOOL_OFFSET_M = 0.5  # a longer tool is a typo (mm for m), not a Delta's tool


class ToolSettings(_Section):
    """The tool on the platform (kinematics/tool.py ``Tool``): operators command its tip.

    Without this section the offset is zero and the tip is the platform centre (the
    behaviour before tools). Frames: docs/kinematics.md, "The tool tip".
    """

    offset_m: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0),
        description="tool tip in the platform frame at wrist angle phi = 0 [m], e.g. "
        "[0, 0, -0.05] for a 5 cm tool pointing down",
    )

    @field_validator("offset_m")
    @classmethod
    def _sensible(cls, offset: tuple[float, float, float]) -> tuple[float, float, float]:
        if not all(math.isfinite(v) for v in offset):
            raise ValueError(f"must be three finite numbers [m], got {list(offset)}")
        length = math.hypot(*offset)
        if length > MAX_TOOL_OFFSET_M:
            raise ValueError(
                f"the tip is {length:.3f} m from the platform centre, over "
                f"{MAX_TOOL_OFFSET_M} m (metres, not millimetres?)"
            )
        return offset

    def build(self, wrist: bool = False) -> Tool:
        """The kinematics tool; ``wrist``: a 4th axis turns it about z (the [wrist] section)."""
        return Tool(offset_m=self.offset_m, wrist=wrist)


class HardwareSettings(_Section):
    """Which servo bus drives the robot."""

    backend: Literal["sim", "emulated", "dynamixel"] = Field(
        "sim",
        description="sim: the MuJoCo twin (its own process); emulated: the pty servo "
        "emulator through the real driver; dynamixel: real servos",
    )
    port: str = Field("/dev/ttyUSB0", description="serial port of the bus (dynamixel)")
    baud: int = Field(1_000_000, ge=9600, le=10_500_000, description="bus baud rate [bit/s]")
    max_tries: int = Field(3, ge=1, le=10, description="tries per bus transaction")
    sim_process: bool = Field(
        True,
        description="sim: step the twin in its own process (off the control loop's GIL); "
        "false steps it in a thread of the server",
    )
    joints: list[JointSettings] = Field(default_factory=_default_joints, min_length=3, max_length=3)
    sim: SimSettings = SimSettings()
    operating_mode: Literal["position", "current_based_position"] = Field(
        "position",
        description="the legs' servos' Operating Mode, written with torque off at start: "
        "position (3), or current_based_position (5: the motor current, and so the torque, "
        "never above goal_current_a)",
    )
    goal_current_a: FiniteFloat | Triple = Field(
        default=XM430_CURRENT_LIMIT_A,
        description="Goal Current of the legs' servos [A], one for all or one per leg "
        f"(0 < value <= {XM430_CURRENT_LIMIT_A:.4g}, the XM430-W210's Current Limit); in "
        "current_based_position it bounds each joint's torque to Kt * goal_current_a",
    )

    @field_validator("goal_current_a")
    @classmethod
    def _within_current_limit(cls, value: float | tuple[float, ...]) -> float | tuple[float, ...]:
        for current in value if isinstance(value, tuple) else (value,):
            if not 0 < current <= XM430_CURRENT_LIMIT_A:
                raise ValueError(
                    f"goal_current_a {current} A must be > 0 and <= "
                    f"{XM430_CURRENT_LIMIT_A:.4g} A (the XM430-W210's Current Limit, "
                    "1193 units of 2.69 mA)"
                )
        return value

    def goal_currents_a(self) -> tuple[float, float, float]:
        """`goal_current_a` per leg [A], shape (3,)."""
        value = self.goal_current_a
        return tuple(value) if isinstance(value, tuple) else (value, value, value)  # type: ignore[return-value]


class LoopSettings(_Section):
    """The control loop's timing."""

    rate_hz: float = Field(200.0, gt=0, le=2000, description="control loop rate [Hz]")
    realtime: bool = Field(
        True,
        description="the robot node's loop thread asks for SCHED_FIFO (needs root or "
        "CAP_SYS_NICE; its status says whether it got it)",
    )
    priority: int = Field(50, ge=1, le=99, description="its SCHED_FIFO priority")
    cpu: int | None = Field(None, ge=0, description="the one CPU its thread runs on (None: any)")
    spin_s: float = Field(
        3e-4, ge=0, le=2e-3, description="busy-wait before each deadline [s] (timer slack)"
    )


class ControlSettings(_Section):
    """How the loop turns goals into servo goals (app/control/gravity.py)."""

    gravity_compensation: bool | None = Field(
        None,
        description="shift each joint's servo goal by its predicted sag under gravity "
        "(gravity torque / the position loop's stiffness), so the arm rests on its goal; "
        "unset: on for a rotary Delta that has gravity (the twin, real servos), off on "
        "the emulator (its servos carry no load) and for linear Deltas",
    )
    payload_kg: float = Field(
        0.0, ge=0, le=2.0, description="load on the platform the compensation holds up [kg]"
    )


class LimitSettings(_Section):
    """Where and how fast the platform may go; every goal passes these (app/control/gate.py)."""

    joint_speed_rad_s: float = Field(
        7.5, gt=0, description="largest commanded joint speed [rad/s] (XM430-W210: 8.1 no-load)"
    )
    workspace_margin_m: float = Field(0.002, ge=0, description="distance kept from the boundary")
    z_max_m: float = Field(-0.06, description="highest platform position allowed [m]")
    min_dexterity: float = Field(0.02, ge=0, lt=1, description="1/cond(J) kept above this")


class JogSettings(_Section):
    """Jerk-limited motion to a goal (jog steps, moves), per Cartesian axis."""

    max_velocity_m_s: float = Field(0.5, gt=0, description="jog speed per axis [m/s]")
    max_acceleration_m_s2: float = Field(4.0, gt=0, description="per axis [m/s^2]")
    max_jerk_m_s3: float = Field(100.0, gt=0, description="per axis [m/s^3]")
    step_m: float = Field(0.005, gt=0, le=0.1, description="default jog step [m]")
    hold_timeout_s: float = Field(
        0.15, gt=0, le=2.0, description="a held jog stops this long after its last heartbeat [s]"
    )
    confirm_move_m: float = Field(
        0.05, gt=0, description="the dashboard asks before a typed move longer than this [m]"
    )
    home_m: tuple[float, float, float] = Field(
        (0.0, 0.0, -0.24),
        description="the tool tip point the dashboard's Go home button goes to [m]",
    )


class SafetySettings(_Section):
    """When the loop faults, and what e-stop and shutdown do to the servos' torque."""

    following_error_rad: float = Field(0.35, gt=0, description="trip above this |cmd - meas|")
    following_error_time_s: float = Field(0.5, ge=0, description="... held this long [s]")
    stale_feedback_s: float = Field(
        0.5,
        gt=0,
        description="fault a motion when the simulator's time stood still this long [s]",
    )
    max_missed_reads: int = Field(10, ge=1, description="fault after this many failed reads")
    estop_action: Literal["hold", "release"] = Field("hold", description="torque on e-stop")
    torque_off_on_exit: bool = Field(True, description="relax the servos on shutdown")
    torque_on_limit_slack_rad: float = Field(
        0.2,
        ge=0,
        le=0.35,
        description="torque on a relaxed arm resting up to this far past a joint limit [rad] "
        "holds it, then steps it back inside at the joint speed limit; farther: refused",
    )


class ServerSettings(_Section):
    """The HTTP/WebSocket server, the 3D scene and who may take control."""

    host: str = Field("127.0.0.1", description="bind address; others need a token")
    http_port: int = Field(8000, ge=0, le=65535, description="HTTP/WebSocket port")
    viser_port: int = Field(8080, ge=0, le=65535, description="3D scene port")
    scene: bool = Field(True, description="serve the 3D scene (viser) on viser_port")
    token: str | None = Field(None, min_length=8, description="required for control if set")
    allowed_hosts: tuple[str, ...] = Field(
        (),
        description="Host names accepted besides localhost, IP addresses and `host` "
        '(DNS rebinding check; "*": any)',
    )
    allowed_origins: tuple[str, ...] = Field(
        (),
        description="web origins (scheme://host:port) that may call the API and the scene "
        "besides the server's own pages",
    )
    telemetry_hz: float = Field(50.0, gt=0, le=200, description="WebSocket telemetry rate")
    lease_timeout_s: float = Field(30.0, gt=0, description="control lease lapses when idle")
    command_timeout_s: float = Field(
        2.0,
        gt=0,
        le=60,
        description="a command (goal, jog, torque, e-stop, reset) waits this long for the "
        "control loop to run it, then is answered 503",
    )
    max_body_bytes: int = Field(
        1 << 20, ge=1024, description="larger request bodies are refused unread (413) [bytes]"
    )
    estop_listener: bool = Field(
        True, description="a POST /estop listener in its own thread, beside the event loop"
    )
    estop_port: int = Field(
        0, ge=0, le=65535, description="its port (0: any free one; /api/info says which)"
    )


class LinkSettings(_Section):
    """The link between the station (``deltadash serve``) and the robot node (``deltadash
    robot``), over Eclipse Zenoh (docs/server.md, "The robot node")."""

    robot: str = Field(
        "embedded",
        description='where the loop runs: "embedded" (serve starts a robot node as its '
        'child process), "in-process" (a thread of the station: tests and the headless '
        "run), or the Zenoh endpoint of a robot node elsewhere, e.g. tcp/192.168.1.20:7447",
    )
    listen: str = Field(
        "tcp/127.0.0.1:7447",
        description="the Zenoh endpoint a robot node listens on (deltadash robot --listen)",
    )
    key_prefix: str = Field(
        "deltadash/robot",
        pattern=r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$",
        description="the robot node's keys are under this (one prefix per robot)",
    )
    heartbeat_s: float = Field(
        0.02, gt=0, le=1, description="a station says it is alive this often [s]"
    )
    state_hz: float = Field(
        200.0,
        gt=0,
        le=2000,
        description="the robot node publishes its state at most this often [Hz] (every tick "
        "of a 200 Hz loop; a station recording a run gets every tick anyway)",
    )
    station_timeout_s: float = Field(
        0.06,
        gt=0,
        le=5,
        description="a robot node that hears no heartbeat this long stops the operator's "
        "motion and holds [s]",
    )
    robot_timeout_s: float = Field(
        0.5,
        gt=0,
        le=10,
        description="a station that gets no state this long says robot offline [s]",
    )
    on_station_lost: Literal["stop", "continue"] = Field(
        "stop",
        description="a run or a hold-in-world when the station is lost: stop and hold, or "
        "carry on to its end (operator motion always stops)",
    )
    take_over: bool = Field(
        False,
        description="a station takes the robot's link from another live station (logged)",
    )
    user: str | None = Field(None, description="Zenoh user name (with password): the link's login")
    password: str | None = Field(None, min_length=8, description="Zenoh password")
    tls_root_ca: str | None = Field(
        None, description="TLS: the CA certificate file a station checks the node with"
    )
    tls_certificate: str | None = Field(None, description="TLS: this side's certificate file")
    tls_private_key: str | None = Field(None, description="TLS: this side's private key file")


_ROS_NAME = r"^[A-Za-z_~/][A-Za-z0-9_/~]*$"


class Ros2Settings(_Section):
    """deltadash as a ROS 2 node on its robot node's Zenoh session (docs/ros2.md): what it
    publishes (on by default), what it takes (each opt-in), names and frames."""

    publish: bool = Field(
        True, description="publish the robot's ROS 2 topics on the link's session"
    )
    domain_id: int = Field(0, ge=0, le=232, description="ROS_DOMAIN_ID")
    distro: Literal["jazzy", "humble"] = Field(
        "jazzy",
        description="the ROS 2 distribution the graph runs: jazzy (and later) carries type "
        "hashes (RIHS01); humble's rmw_zenoh writes TypeHashNotSupported",
    )
    form: Literal["rmw_zenoh", "bridge"] = Field(
        "rmw_zenoh",
        description="rmw_zenoh's keys and liveliness tokens, or zenoh-bridge-ros2dds's keys "
        "(the topic's name)",
    )
    connect: tuple[str, ...] = Field(
        (),
        description="the ROS 2 graph's Zenoh router (rmw_zenohd, e.g. tcp/127.0.0.1:7447): "
        "the ROS side then has a Zenoh session of its own connected to it (the link's keys "
        "and login stay off that network), tried until it answers; empty: ROS peers "
        "connect to the robot node's own endpoint",
    )
    node_name: str = Field("deltadash", pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")
    namespace: str = Field("/", pattern=_ROS_NAME, description="the node's namespace")
    rate_hz: float = Field(
        100.0, gt=0, le=1000, description="joint states, tf and the tip's pose, this often"
    )
    joint_states_topic: str = Field("joint_states", pattern=_ROS_NAME)
    tip_pose_topic: str = Field(
        "delta/tip_pose", pattern=_ROS_NAME, description="the tip in the base frame"
    )
    tip_world_topic: str = Field(
        "delta/tip_pose_world", pattern=_ROS_NAME, description="the tip in the world while holding"
    )
    diagnostics_topic: str = Field("diagnostics", pattern=_ROS_NAME)
    tip_wrench_topic: str = Field(
        "delta/tip_wrench",
        pattern=_ROS_NAME,
        description="the tip's contact force estimate, base frame (WrenchStamped; the force "
        "the tip applies)",
    )
    tracked_goal_topic: str = Field(
        "delta/goal",
        pattern=_ROS_NAME,
        description="the goal the loop tracks (the tip in the base frame, PoseStamped), in "
        "run logs",
    )
    run_log: bool = Field(
        True,
        description="write each run's log as a ROS 2 bag too: runs/<id>/log.ros2.mcap "
        "(docs/ros2.md, 'Run logs as ROS 2 data')",
    )
    world_frame: str = Field("map", description="the world's frame id (REP 105)")
    drone_frame: str = Field("base_link", description="the drone body's frame id (FLU)")
    base_frame: str = Field("delta_base", description="the Delta's base frame id")
    platform_frame: str = Field("delta_platform")
    tip_frame: str = Field("delta_tip", description="the tool tip's frame id")
    joint_names: tuple[str, str, str] = Field(("delta_joint_1", "delta_joint_2", "delta_joint_3"))
    wrist_joint_name: str = Field("delta_wrist")
    # what it takes (each opt-in)
    pose_input: Literal["off", "odometry", "pose", "px4"] = Field(
        "off",
        description="the drone's pose for hold-in-world from a ROS topic: nav_msgs/Odometry, "
        "geometry_msgs/PoseStamped (mavros, vrpn) or px4_msgs/VehicleOdometry (NED/FRD)",
    )
    pose_topic: str | None = Field(
        None,
        pattern=_ROS_NAME,
        description="its topic (None: odom, mavros/local_position/pose or "
        "/fmu/out/vehicle_odometry by pose_input)",
    )
    input_world_frames: tuple[str, ...] = Field(
        ("map", "odom", "world"),
        description="the frame ids a world-frame input may carry (ENU, z up: REP 105)",
    )
    goal_input: Literal["off", "pose", "point"] = Field(
        "off",
        description="take tip goals from a ROS topic (PoseStamped or PointStamped, in the "
        "base frame or, while holding in the world, in the world frame); they move the "
        "robot only once the operator who holds control arms them (PUT /api/ros2/goals)",
    )
    goal_topic: str = Field("delta/tip_goal", pattern=_ROS_NAME)
    inputs_trusted: bool = Field(
        False,
        description="with server.token set, the ROS inputs are taken only with this: ROS "
        "messages carry no credentials, the Zenoh network (its router's access control) "
        "is the trust boundary",
    )
    stamp_future_s: float = Field(
        0.05, ge=0, le=10, description="refuse an input stamped further ahead than this"
    )
    stamp_age_s: float = Field(
        0.5, gt=0, le=60, description="refuse an input stamped longer ago than this"
    )
    input_silent_s: float = Field(
        1.0, gt=0, le=60, description="an input with nothing for this long is named silent"
    )
    max_input_hz: float = Field(
        1000.0, gt=0, le=100000, description="an input faster than this drops the excess"
    )


class FoxgloveSettings(_Section):
    """The station's Foxglove live server (docs/foxglove.md): the robot's joints, frames,
    tracking error, loop health, faults and runs, for the Foxglove app (opt-in)."""

    enabled: bool = Field(False, description="serve the robot to Foxglove on `port`")
    host: str | None = Field(
        None,
        description="bind address (unset: [server] host); with server.token set, clients "
        "send it (?token= or a Bearer header), and beyond loopback one must be set",
    )
    port: int = Field(8765, ge=0, le=65535, description="its WebSocket port (0: any free one)")
    rate_hz: float = Field(
        50.0, gt=0, le=200, description="joint states, frames and plots, at most this often"
    )
    goal_frame: str = Field("delta_goal", description="the tip's goal's frame id")


class RunSettings(_Section):
    """Recorded runs: where their logs go and how they are followed and scored."""

    folder: str = Field("runs", description="where run logs and reports go (created)")

    @property
    def folder_path(self) -> Path:
        return Path(self.folder).expanduser()

    feedforward_lead_s: float = Field(
        0.02, ge=0, le=0.5, description="feed-forward: command the trajectory this far ahead [s]"
    )
    stats_skip_s: float = Field(
        0.5, ge=0, description="tracking stats leave out the first seconds of the timed part"
    )
    max_samples: int = Field(
        150_000, ge=1000, description="longest run, in loop periods (200 Hz: 750 s) [samples]"
    )
    plan_timeout_s: float = Field(
        5.0, gt=0, description="a run whose planning and check took longer is not started [s]"
    )
    max_pause_s: float = Field(
        600.0,
        gt=0,
        le=86_400,
        description="a run paused (Pause, M0, M1, a single step's stop) longer than this "
        "is aborted; while paused its log keeps one row a second [s]",
    )


class WorldSettings(_Section):
    """Hold-in-world: the Delta base on the drone, and how drone poses are vetted."""

    mount_position_m: tuple[float, float, float] = Field(
        (0.0, 0.0, -0.08), description="Delta base origin in the drone body frame [m]"
    )
    mount_quaternion: tuple[float, float, float, float] = Field(
        (1.0, 0.0, 0.0, 0.0), description="base orientation in the body frame (w, x, y, z)"
    )
    stale_after_s: float = Field(0.05, gt=0, description="older pose: freeze the goal, warn")
    lost_after_s: float = Field(0.5, gt=0, description="older pose: fault")
    max_jump_m: float = Field(0.05, gt=0, description="a sample jumping further is dropped")
    servo_lag_s: float = Field(
        0.03, ge=0, le=0.5, description="compensation: predict this far past the pose's age [s]"
    )
    udp_port: int | None = Field(None, ge=1, le=65535, description="UDP JSON pose input port")
    mavlink_url: str | None = Field(
        None, description="pymavlink connection for ODOMETRY, e.g. udpin:0.0.0.0:14550"
    )
    udp_trusted: bool = Field(
        False,
        description="with server.token set: take UDP poses without a token (a trusted "
        'local bridge); otherwise each datagram carries the token as "token"',
    )
    mavlink_trusted: bool = Field(
        False,
        description="with server.token set: take MAVLink ODOMETRY unsigned (a trusted "
        "link); otherwise it needs mavlink_signing_key or is refused",
    )
    mavlink_signing_key: str | None = Field(
        None,
        min_length=8,
        description="MAVLink2 signing passphrase (key: its SHA-256, as MAVProxy's 'signing "
        "setup'): unsigned or wrongly signed messages are refused",
    )

    @property
    def mavlink_signing_key_bytes(self) -> bytes | None:
        """The 32-byte signing key: SHA-256 of ``mavlink_signing_key`` (None without)."""
        if self.mavlink_signing_key is None:
            return None
        return hashlib.sha256(self.mavlink_signing_key.encode()).digest()


class ProgramSettings(_Section):
    """G-code programs (app/programs/): how they are planned and what their check accepts."""

    chord_tolerance_m: float = Field(
        1e-5,
        gt=0,
        description="largest distance between an arc and the loop's chord from one sample "
        "to the next (caps the speed on arcs) [m]",
    )
    max_acceleration_m_s2: float = Field(
        2.0, gt=0, description="path acceleration of G1/G2/G3, tangential and normal [m/s^2]"
    )
    max_jerk_m_s3: float = Field(50.0, gt=0, description="path jerk of G1/G2/G3 [m/s^3]")
    joint_acceleration_rad_s2: float = Field(
        200.0, gt=0, description="largest joint acceleration a program may ask [rad/s^2]"
    )
    max_torque_ratio: float = Field(
        0.8,
        gt=0,
        le=1.0,
        description="largest |torque| / the servo's torque at that speed (the rotor "
        "inertia is uncertain by x3: keep a margin)",
    )
    payload_kg: float = Field(0.0, ge=0, description="load on the platform for the torque check")
    start_m: tuple[float, float, float] = Field(
        (0.0, 0.0, -0.24), description="where an offline check assumes the tool tip starts [m]"
    )
    work_offset_m: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0), description="G54: the program origin in the base frame [m]"
    )
    max_lines: int = Field(100_000, ge=1, description="longest program accepted [lines]")
    max_samples: int = Field(
        1_000_000, ge=1000, description="longest planned program, in loop periods [samples]"
    )
    path_points: int = Field(
        2000, ge=2, le=100_000, description="points of the decimated path in a report"
    )
    dry_run_max_s: float = Field(
        60.0,
        gt=0,
        le=3600,
        description="longest program the dry run plays on the twin [s] (its physics costs "
        "about a millisecond of CPU per loop tick)",
    )
    check_timeout_s: float = Field(
        300.0,
        gt=0,
        le=3600,
        description="longest a check or dry run may take in its worker process, the "
        "worker's start included; beyond, the worker is stopped and the request is a 503 [s]",
    )


class ContactSettings(_Section):
    """``[contact]``: the tip's force estimate, touch, the compliant press and the force
    limits (app/control/contact.py, docs/contact.md)."""

    estimate: bool = Field(
        True,
        description="estimate the tip's contact force each tick from the servos' currents "
        "(rotary Deltas whose bus carries a load: the twin, real servos)",
    )
    force_limit_n: float = Field(
        15.0,
        gt=0,
        le=60.0,
        description="the most a touch or a press may push [N]: past it the loop faults "
        "and holds; no request may ask for more",
    )
    collision_stop: bool = Field(
        False,
        description="force-limited motion: any motion whose estimated contact force passes "
        "collision_force_n stops and faults, saying the force and the point",
    )
    collision_force_n: float = Field(
        6.0, gt=0, le=60.0, description="the force that counts as a collision [N]"
    )
    detect_force_n: float = Field(
        0.8,
        gt=0,
        le=20.0,
        description="a touch counts contact from this force along its direction [N] "
        "(above the estimate's noise while moving slowly)",
    )
    touch_speed_m_s: float = Field(
        0.01, ge=1e-4, le=0.1, description="a touch's default approach speed [m/s]"
    )
    touch_force_n: float = Field(2.0, gt=0, le=60.0, description="a touch's default set force [N]")
    touch_max_travel_m: float = Field(
        0.05, gt=0, le=0.3, description="a touch's default travel before 'no contact' [m]"
    )
    admittance_m_per_n_s: float = Field(
        0.02,
        gt=0,
        le=0.1,
        description="the compliant press's gain: speed along the pressed direction per N "
        "of force error [m/(N s)]",
    )
    press_travel_m: float = Field(
        0.02,
        gt=0,
        le=0.1,
        description="how far a press may move its point along the direction to keep the "
        "force [m]; at the end of it the contact counts as lost",
    )

    @model_validator(mode="after")
    def _ordered(self) -> ContactSettings:
        if self.detect_force_n >= self.force_limit_n:
            raise ValueError(
                f"contact.detect_force_n ({self.detect_force_n} N) must be below "
                f"contact.force_limit_n ({self.force_limit_n} N)"
            )
        if self.touch_force_n > self.force_limit_n:
            raise ValueError(
                f"contact.touch_force_n ({self.touch_force_n} N) is over "
                f"contact.force_limit_n ({self.force_limit_n} N)"
            )
        if self.touch_force_n <= self.detect_force_n:  # a touch would stop before contact
            raise ValueError(
                f"contact.touch_force_n ({self.touch_force_n} N) must be above "
                f"contact.detect_force_n ({self.detect_force_n} N)"
            )
        return self


class Settings(BaseSettings):
    """Everything ``deltadash serve`` can be told."""

    model_config = SettingsConfigDict(
        env_prefix="DELTADASH_", env_nested_delimiter="__", extra="forbid", frozen=True
    )
    robot: RobotSettings = RobotSettings()
    tool: ToolSettings = ToolSettings()
    hardware: HardwareSettings = HardwareSettings()
    loop: LoopSettings = LoopSettings()
    control: ControlSettings = ControlSettings()
    limits: LimitSettings = LimitSettings()
    jog: JogSettings = JogSettings()
    safety: SafetySettings = SafetySettings()
    server: ServerSettings = ServerSettings()
    runs: RunSettings = RunSettings()
    world: WorldSettings = WorldSettings()
    programs: ProgramSettings = ProgramSettings()
    wrist: WristSettings = WristSettings()
    link: LinkSettings = LinkSettings()
    ros2: Ros2Settings = Ros2Settings()
    foxglove: FoxgloveSettings = FoxgloveSettings()
    contact: ContactSettings = ContactSettings()

    @model_validator(mode="after")
    def _wrist_id_free(self) -> Settings:
        legs = [joint.servo_id for joint in self.hardware.joints]
        if self.wrist.enabled and self.wrist.servo_id in legs:
            raise ValueError(
                f"wrist.servo_id {self.wrist.servo_id} is a leg's servo id (legs: {legs})"
            )
        return self

    @model_validator(mode="after")
    def _ros_inputs_trusted(self) -> Settings:
        ros = self.ros2
        takes = [n for n in ("pose_input", "goal_input") if getattr(ros, n) != "off"]
        if self.server.token is not None and takes and not ros.inputs_trusted:
            raise ValueError(
                f"ros2.{takes[0]}: ROS messages carry no credentials and server.token is set; "
                "take them only on a Zenoh network you trust (its router's access control): "
                "set ros2.inputs_trusted = true"
            )
        return self

    def bus_joints(self) -> list[JointSettings]:
        """The servos on the bus in bus order: the three legs, then the wrist if enabled."""
        joints = list(self.hardware.joints)
        return joints + [self.wrist] if self.wrist.enabled else joints

    def gravity_on(self, carries_load: bool = True) -> bool:
        """Whether the loop compensates gravity on a bus that ``carries_load`` (a real or
        simulated arm; a fake or the emulator's servos carry none): ``[control]
        gravity_compensation`` when set, else on for a rotary Delta whose bus carries a
        load, except on the emulator backend."""
        wanted = self.control.gravity_compensation
        if wanted is None:
            return (
                carries_load and self.robot.type == "rotary" and self.hardware.backend != "emulated"
            )
        return wanted

    @model_validator(mode="after")
    def _gravity_model(self) -> Settings:
        if self.control.gravity_compensation and self.robot.type != "rotary":
            raise ValueError(
                "control.gravity_compensation: only rotary Deltas have a gravity model "
                f"(robot.type is {self.robot.type!r})"
            )
        return self

    @model_validator(mode="after")
    def _legs_buildable(self) -> Settings:
        if self.robot.legs is None:
            return self
        if self.robot.type != "rotary":
            raise ValueError(
                "robot.legs: per-leg geometry is for rotary Deltas "
                f"(robot.type is {self.robot.type!r})"
            )
        try:
            self.robot.build()
        except DeltaError as exc:  # name the field: l[0] is lower_link_m's first value
            field = {v: k for k, v in _LEGS.items()}.get(str(exc).split("[")[0])
            raise ValueError(f"robot.legs{'.' + field if field else ''}: {exc}") from exc
        return self

    @model_validator(mode="after")
    def _twin_buildable(self) -> Settings:
        robot = self.robot.symmetric()  # the twin's truth is around the drawing's values
        if isinstance(robot, RotaryDelta):
            self.hardware.sim.true_robot(robot)  # raises naming the field
        return self

    @classmethod
    def settings_customise_sources(
        cls, settings_cls: type[BaseSettings], init_settings: Any, env_settings: Any, **_: Any
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        toml_file = TomlConfigSettingsSource(settings_cls, toml_file=_TOML_PATH.get())
        return init_settings, env_settings, toml_file


class ConfigError(ValueError):
    """A config that cannot be used; the message lists each bad field and why."""


def load_settings(path: str | Path | None = None, **overrides: Any) -> Settings:
    """Settings from defaults, the TOML file at ``path``, the environment and ``overrides``.

    ``overrides`` are nested dicts per section, e.g. ``hardware={"backend": "dynamixel"}``.

    Raises:
        ConfigError: naming every bad field (``hardware.baud: ...``) or an unreadable file.
    """
    toml_path = Path(path) if path is not None else None
    if toml_path is not None and not toml_path.is_file():
        # pydantic-settings skips a missing file; a path given on purpose must exist.
        raise ConfigError(f"cannot read config {toml_path}: not a file")
    token = _TOML_PATH.set(toml_path)
    try:
        return Settings(**overrides)
    except ValidationError as exc:
        lines = [  # a check across sections has no location: its message names the field
            f"{'.'.join(map(str, e['loc']))}: {e['msg']}"
            if e["loc"]
            else e["msg"].removeprefix("Value error, ")
            for e in exc.errors()
        ]
        raise ConfigError("bad config:\n  " + "\n  ".join(lines)) from None
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"cannot read config {toml_path}: {exc}") from None
    finally:
        _TOML_PATH.reset(token)

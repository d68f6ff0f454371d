"""Response bodies of the API: what the dashboard (static/js/) and any client read.

Built from what serialize.py and the routers produce (same names, same nesting), with
``extra="forbid"`` so a key added on one side and not the other fails the tests instead of
being dropped silently. A shape the domain already declares as a record (the loop's
timing figures, the bus's counters, the lease's public view) is made from that record
(app/server/api/records.py), not written again. SI units, base frame; null where a value
is unknown (no read yet, FK failed).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, create_model

from app.control.authority import LeaseView
from app.control.timing import TimingStats
from app.server.api.records import model_of
from hardware.bus import READINGS, BusStats

MaybeFloat = float | None
MaybeVector3 = Annotated[
    list[MaybeFloat], Field(min_length=3, max_length=3, description="3 values, null if unknown")
]


class _Out(BaseModel):
    model_config = ConfigDict(extra="forbid")


class FaultOut(_Out):
    """Why the robot stopped, one entry per cause however often it recurs.

    source is bus, servo, following, source, gate or loop; kind the stable part of the
    cause; reason the latest text; count how often it was seen, first and last at loop
    times [s]; time_s is first_time_s (kept for older clients).
    """

    source: str
    kind: str
    reason: str
    servo_id: int | None = None
    time_s: float
    count: int = Field(ge=1)
    first_time_s: float
    last_time_s: float


class _JointsRead(_Out):
    servo_ids: list[int]
    position_rad: MaybeVector3
    commanded_rad: MaybeVector3


# the servo readings, one field each, as hardware/bus.py declares them (READINGS)
_JointsReadings = create_model(
    "JointsReadings",
    __base__=_JointsRead,
    **{
        name: (MaybeVector3, Field(description=f"{description} [{unit}]"))
        for name, (unit, description) in READINGS.items()
    },
)


class JointsStatus(_JointsReadings):  # type: ignore[misc,valid-type]
    moving: list[bool]
    hardware_errors: list[list[str]] = Field(description="per servo, its hardware error flags")
    torque_enabled: list[bool | None] = Field(
        description="per servo, Torque Enable as read from it (null: the bus does not say); "
        "false for a servo whose shutdown (overload, overheating) turned its torque off"
    )


class PlatformStatus(_Out):
    """The end effector [m]: the tool tip measured (FK plus the tool offset), commanded,
    their difference, and an external measurement (e.g. motion capture) when one is fed in;
    the platform centre and the wrist angle. Without [tool] the tip is the platform centre."""

    position_m: MaybeVector3 = Field(description="the tool tip, measured [m]")
    platform_m: MaybeVector3 = Field(description="the platform centre, measured (FK) [m]")
    phi_rad: float = Field(
        description="the wrist angle the tool is at [rad]: the wrist servo's reading; "
        "0 without a wrist"
    )
    commanded_m: MaybeVector3
    error_m: MaybeVector3 = Field(
        description="commanded - measured [m]; null without a setpoint (torque off, e-stop, fault)"
    )
    external_m: MaybeVector3


class GoalStatus(_Out):
    position_m: MaybeVector3 = Field(description="the tool tip goal [m]")
    phi_rad: float | None = Field(
        None,
        description="the wrist's goal [rad] (as commanded while it holds); null without a wrist",
    )


TimingStatsOut = model_of(
    TimingStats,
    "TimingStatsOut",
    base=_Out,
    doc="Loop timing; jitter is how late a tick started after its deadline [ms].",
    describe={"longest_gap_ms": "the longest time between two ticks' starts [ms]"},
)


class LoopHealthOut(_Out):
    """The loop-health light over the last 10 s (app/control/loop_health.py): red past a
    run-health limit (over 1 % overruns, a gap over 20 ms, rate under 95 %), amber halfway
    (0.5 %, 10 ms, 97.5 %), green otherwise, unknown before two ticks."""

    level: Literal["green", "amber", "red", "unknown"]
    reasons: list[str] = Field(description="the limits of that level passed, in words")
    window_s: float = Field(description="the window judged [s]")
    rate_hz: float
    target_hz: float
    rate_share: float = Field(description="rate_hz / target_hz")
    p99_ms: float = Field(description="99th percentile of tick lateness [ms]")
    overruns: int
    ticks: int
    overrun_share: float = Field(description="overruns / ticks")
    longest_gap_ms: float = Field(description="the longest time between two ticks' starts [ms]")


class LoopStatus(TimingStatsOut):  # type: ignore[misc,valid-type]
    """The last 10 s at top level (overruns and ticks since start), both in full, and the
    health light judged on the last 10 s."""

    since_start: TimingStatsOut
    last_10s: TimingStatsOut
    health: LoopHealthOut


class BusStatusOut(  # type: ignore[misc,valid-type]
    model_of(
        BusStats,
        "BusCounters",
        base=_Out,
        describe={
            "discarded": "status packets discarded as answers to another request (late, duplicated)"
        },
    )
):
    """Counters since connect, and reads the loop missed."""

    missed_reads: int


class PoseSourceOut(_Out):
    """One pose source (http, websocket, udp, mavlink) and what it accepts."""

    name: str = Field(description="http | websocket | udp | mavlink")
    enabled: bool = Field(description="udp and mavlink: configured ([world] udp_port, mavlink_url)")
    rule: str = Field(
        description="what it takes: open (no server.token) | token (the token with each "
        "request, frame or datagram) | trusted ([world] udp_trusted / mavlink_trusted) | "
        "signed (MAVLink2 signing, [world] mavlink_signing_key) | refused (a token is set "
        "and MAVLink is neither trusted nor signed: every message is refused)"
    )
    alive: bool | None = Field(
        description="udp and mavlink: the listener thread runs (false: dead, see last_error; "
        "POST /api/reset restarts it); null for the others"
    )
    accepted: int | None = Field(description="samples the tracker kept from this input")
    errors: int | None = Field(description="messages refused as malformed")
    refused: int | None = Field(description="messages refused by the rule (token, signature)")
    restarts: int | None = Field(description="times the listener was restarted")
    last_error: str | None = Field(
        description="the last refused message's reason, or why the input stopped"
    )


class PoseInputStatus(_Out):
    """A pose input's health (the drone's, or a platform marker's: ``body``)."""

    state: str = Field(description="ok | stale | lost | none")
    age_s: float | None = Field(description="since the last accepted sample [s]")
    rate_hz: float
    accepted: int
    dropped: int = Field(description="samples dropped: out of order, duplicate or jumping")
    jumps: int
    restarts: int = Field(
        0, description="times the stream started afresh: a sample after lost_after_s of none"
    )
    refused_frames: dict[str, int] = Field(
        default_factory=dict,
        description="MAVLink ODOMETRY messages refused for a frame not taken, by field and "
        "frame, e.g. {'child_frame_id MAV_FRAME_LOCAL_ENU': 3}",
    )
    udp_errors: int | None = Field(
        None,
        description="GET only, with [world] udp_port: datagrams refused (not JSON, a bad "
        "field or body, a missing or wrong token), of both bodies",
    )
    sources: list[PoseSourceOut] | None = Field(
        None, description="GET only: every pose source, what it accepts and its counters"
    )
    # hold-in-world on the page (issue 32): the latest sample, as app/world/poses.py keeps it
    source: str | None = Field(
        None,
        description="the input the latest sample came by: http | websocket | udp | mavlink | "
        "simulated (null: none yet)",
    )
    position_m: list[float] | None = Field(None, description="the latest sample's position [m]")
    quaternion: list[float] | None = Field(
        None, description="the latest sample's attitude (w, x, y, z), body to world"
    )


class ServoRole(_Out):
    """A servo on the bus: its Dynamixel ``id``, its ``role`` and, for a leg, its joint."""

    id: int
    role: Literal["leg", "wrist"]
    joint: int | None = Field(description="1..3 for a leg (joint order); null for the wrist")


class ContactStatus(_Out):
    """The tip's contact force this tick (docs/contact.md): the force the tip applies on
    what it touches, base frame [N], from the servos' currents through the model."""

    force_n: MaybeVector3 = Field(description="contact force, base frame [N]")
    std_n: MaybeVector3 = Field(description="its 1-sigma error per axis [N]")
    magnitude_n: MaybeFloat = Field(description="|force_n| [N]")
    valid: bool = Field(description="the estimate could be made this tick")
    reason: str | None = Field(description="why not, when not valid")


class TouchOut(_Out):
    """How the last touch ended (app/control/touch.py)."""

    outcome: Literal["touching", "contact", "no contact", "stopped"]
    contact_point_m: MaybeVector3 = Field(description="where the surface starts, base frame [m]")
    force_n: MaybeVector3 = Field(description="the contact force at its end [N]")
    peak_force_n: MaybeFloat = Field(description="the largest force along its direction [N]")
    travel_m: MaybeFloat = Field(description="the furthest the command went along it [m]")
    direction: MaybeVector3 = Field(description="the unit direction it moved along")
    source_id: str | None
    joints_at_contact_rad: MaybeVector3 = Field(
        description="the legs' joints as read when contact was seen [rad]"
    )
    reason: str | None = Field(None, description="why it was 'stopped' (null otherwise)")


class ContactLimitsOut(_Out):
    force_limit_n: float = Field(description="the most a touch or press may push [N]")
    collision_stop: bool = Field(description="force-limited motion is on")
    collision_force_n: float = Field(description="the force that counts as a collision [N]")
    detect_force_n: float = Field(description="a touch sees contact from this force [N]")
    press_travel_m: float = Field(description="how far a press may shift its point [m]")


class ContactDefaultsOut(_Out):
    speed_m_s: float
    force_n: float
    max_travel_m: float


class ContactOut(_Out):
    """GET /api/contact: the estimate now, the last touch, the limits and touch defaults."""

    estimate: ContactStatus
    touch: TouchOut | None
    limits: ContactLimitsOut
    defaults: ContactDefaultsOut


class WristServoStatus(_Out):
    """The wrist's servo (the fourth on the bus): phi as read and as last written [rad],
    and its readings as the legs' servos have them in ``joints``."""

    servo_id: int
    position_rad: MaybeFloat = Field(description="phi as read [rad]")
    commanded_rad: MaybeFloat = Field(description="phi as last written [rad]")
    velocity_rad_s: MaybeFloat
    current_a: MaybeFloat
    voltage_v: MaybeFloat
    temperature_c: MaybeFloat
    pwm: MaybeFloat = Field(description="PWM duty cycle, signed (1 = full)")
    hardware_errors: list[str]
    torque_enabled: bool | None


class StatusOut(_Out):
    """GET /api/status: everything about the robot now."""

    mode: str
    backend: str = Field(description="sim | emulated | dynamixel")
    backend_description: str
    torque: bool = Field(
        description="torque asked for and held: false once any servo reads its Torque Enable "
        "off (a shutdown after an overload); joints.torque_enabled says which"
    )
    estopped: bool
    estop_received_unix_s: float | None = Field(
        description="wall-clock time [s since the Unix epoch] the last e-stop press reached "
        "the server (its first request: POST /api/estop or the e-stop listener), before it "
        "was queued to the loop; null: none since the server started"
    )
    estop_arrivals_unix_s: dict[str, float] = Field(
        description="when the last press's requests reached each path [s since the Unix "
        "epoch]: 'listener' (its own thread), 'middleware' (first in the app), 'route' (the "
        "handler, after routing and dependencies); the gaps show where the time goes"
    )
    faults: list[FaultOut]
    faults_dropped: int = Field(description="older causes dropped from the bounded list")
    warning: str | None
    notice: str | None = Field(
        description="about the last motion command, e.g. that it started from the measured "
        "position (the first motion after torque off, an e-stop or a fault)"
    )
    time_s: float
    joints: JointsStatus
    ee: PlatformStatus
    goal: GoalStatus
    loop: LoopStatus
    bus: BusStatusOut
    pose: PoseInputStatus | None
    phase: str = Field(description="a run's phase (approach, timed, stop); empty otherwise")
    gains: dict[str, dict[str, int]] = Field(
        description="the position gains in use per leg servo id, register units: p, i, d, "
        "ff1, ff2 (POST /api/tuning/{run_id}/apply changes them)"
    )
    servo_mode: Literal["position", "current_based_position"] = Field(
        description="the legs' servos' operating mode: position (Dynamixel mode 3) or "
        "current_based_position (mode 5: each joint's motor current, and so its torque, "
        "bounded by goal_current_a); PUT /api/servos/current changes it with torque off"
    )
    goal_current_a: list[float] = Field(
        description="the legs' Goal Current per leg in joint order [A], as last written "
        "(a bound on the motor current in current_based_position; XM430-W210 up to 3.209)"
    )
    servos: list[ServoRole] = Field(
        description="every servo on the bus in bus order with its role: the legs (as "
        "joints.servo_ids lists them, which stays the legs'), then the wrist's if fitted"
    )
    wrist_servo: WristServoStatus | None = Field(
        description="the wrist's servo as last read (null figures before its first read); "
        "null without a wrist"
    )
    contact: ContactStatus = Field(description="the tip's contact force estimate this tick")


class TelemetryLoop(_Out):
    measured_hz: float
    jitter_p99_ms: float
    overruns: int


class WorldFrame(_Out):
    """Hold-in-world with a known drone pose: world frame [m], error = goal - measured."""

    goal_m: MaybeVector3
    measured_m: MaybeVector3
    error_m: MaybeVector3
    heading_rad: float | None = Field(None, description="with a wrist: world heading kept [rad]")
    heading_error_rad: float | None = Field(
        None, description="with a wrist: heading goal - measured, wrapped [rad]"
    )
    heading_limited: bool | None = Field(
        None, description="with a wrist: its limits cut the heading (held at the limit)"
    )
    drone_pose: list[float | None] | None = Field(
        None, description="the drone's pose the hold works from: x, y, z [m], qw, qx, qy, qz"
    )


class TelemetryEe(_Out):
    """The end effector this tick: tool tip and platform centre [m], wrist angle [rad]."""

    position_m: MaybeVector3
    platform_m: MaybeVector3
    phi_rad: float
    goal_phi_rad: float | None = Field(
        None, description="the wrist's goal [rad] (as commanded while it holds); null without one"
    )


class TelemetryMessage(_Out):
    """One message of the telemetry WebSocket (/api/telemetry), one per loop tick sent."""

    t: float = Field(description="loop time [s]")
    tick: int
    mode: str
    goal_m: MaybeVector3
    commanded_joints_rad: MaybeVector3
    measured_joints_rad: MaybeVector3
    commanded_m: MaybeVector3
    measured_m: MaybeVector3 = Field(description="the tool tip, measured [m] (= ee.position_m)")
    error_m: MaybeVector3 = Field(
        description="commanded - measured [m]; null without a setpoint (torque off, e-stop, fault)"
    )
    current_a: MaybeVector3 = Field(description="the leg servos' current [A], joint order")
    pwm: MaybeVector3 = Field(description="the leg servos' PWM duty (1 = full), joint order")
    ee: TelemetryEe
    loop: TelemetryLoop
    faults: list[FaultOut]
    world: WorldFrame | None
    contact: ContactStatus = Field(description="the tip's contact force estimate this tick")


class AxisStats(_Out):
    """Errors on one axis [m] (reference - measured); NaN-free samples only."""

    mean_m: float
    rmse_m: float
    std_m: float
    max_abs_m: float
    share_under_1cm: float
    share_under_1mm: float


class ErrorStats(_Out):
    x: AxisStats
    y: AxisStats
    z: AxisStats
    samples: int


class AngleStats(_Out):
    """Angle errors [rad] (reference - measured, wrapped); NaN-free samples only."""

    mean_rad: float
    rmse_rad: float
    max_abs_rad: float
    samples: int


class HeadingStats(AngleStats):
    limited_s: float = Field(description="time the wrist's limits cut the heading [s]")


class WorldStats(ErrorStats):
    """Hold runs: world-frame errors, time outside the workspace, and errors inside only;
    with a wrist, the tool's world heading error."""

    outside_s: float
    inside_only: ErrorStats
    heading: HeadingStats | None = None


class LatenessOut(_Out):
    p50: float = Field(description="median lateness of a tick after its deadline [ms]")
    p99: float = Field(description="99th percentile [ms]")
    worst: float = Field(description="largest [ms]")


class RunHealth(BaseModel):
    """The loop's health over the run (app/runs/health.py): ``ok`` false with its reasons
    when the loop or its feedback was not good enough for the run's figures to mean much
    (over 1 % overruns, a gap over 20 ms, stale feedback; the limits are in
    ``thresholds``)."""

    model_config = ConfigDict(extra="allow")
    ok: bool
    reasons: list[str] = Field(description="why not ok, in words; empty when ok")
    rate_hz: float = Field(description="ticks per second over the run [Hz]")
    lateness_ms: LatenessOut
    overruns: int = Field(description="ticks that missed their deadline")
    overrun_share: float = Field(description="overruns / ticks")
    longest_gap_ms: float = Field(description="longest time between two ticks' starts [ms]")
    stale_ticks: int = Field(description="ticks whose read brought no news")
    longest_stale_ms: float = Field(description="longest stretch of stale feedback [ms]")
    thresholds: dict[str, float]


class LineErrorOut(_Out):
    """The tracking error over one G-code program line (|goal - FK| per sample)."""

    line: int = Field(description="program line (1-based)")
    samples: int = Field(description="loop samples spent on the line")
    rmse_m: float | None = Field(
        description="sqrt(mean |e|^2) over the line [m]; null for a line with no sample (a "
        "late tick crossed it whole)"
    )
    max_m: float | None = Field(description="largest |e| over the line [m]; null as rmse_m")


class ProgramStats(BaseModel):
    model_config = ConfigDict(extra="allow")
    lines: list[LineErrorOut] = Field(description="per program line, in execution order")


class RunStats(BaseModel):
    """Empty while a run goes; tracking (goal vs FK), validation (FK vs external) when
    measured, world for hold runs, the loop's health and, for a G-code program, the error
    per program line."""

    model_config = ConfigDict(extra="allow")  # runs saved by older versions load as they are
    tracking: ErrorStats | None = None
    validation: ErrorStats | None = None
    world: WorldStats | None = None
    wrist: AngleStats | None = Field(None, description="with a wrist: phi goal - measured")
    health: RunHealth | None = None
    program: ProgramStats | None = None


class RunProgress(_Out):
    """How far the running run is, in run time [s] (approach, test part, stop)."""

    phase: str = Field(description="approach | timed | hold | stop")
    elapsed_s: float = Field(description="run time since the run started [s]")
    duration_s: float | None = Field(description="the whole run with approach and stop [s]")
    test_elapsed_s: float = Field(description="time into the test part [s]")
    test_duration_s: float | None = Field(description="the test part's length [s]")
    program_line: int | None = Field(
        None, description="a G-code program's line being executed (1-based); null otherwise"
    )
    feed_override: float | None = Field(
        None, description="the feed override set, 0.1 to 1.0 (checked at 1.0: never above)"
    )
    feed_rate: float | None = Field(
        None, description="the rate the path's time runs at now (0: standing, 1: as planned)"
    )
    paused: str | None = Field(
        None, description="why the run stands or is stopping, in words; null: running"
    )
    time_left_s: float | None = Field(
        None, description="the path time left at the feed override [s]"
    )
    optional_stop: bool | None = Field(None, description="M1 stops (the optional stop is on)")
    stop_line: int | None = Field(
        None, description="the program line a single step or an M0 / M1 stops (stopped) at"
    )


class RunOut(_Out):
    """One run, as saved in its run.json, with its test in words and, while it runs, how
    far it is."""

    run_id: str
    kind: str = Field(description="sinusoid | chirp | step | waypoints | hold | program")
    params: dict[str, Any]
    conditions: dict[str, Any] = Field(description="robot, backend, loop rate, joints, gains")
    state: str = Field(
        description="running | done | aborted | interrupted (the server stopped during the "
        "run: its stats are from the ticks logged until then)"
    )
    reason: str | None
    started_at: float = Field(description="Unix time [s]")
    started_at_utc: str = Field(description="started_at in UTC, ISO 8601")
    ended_at: float | None = Field(
        description="Unix time [s]; for an interrupted run, when its logs were last written"
    )
    samples: int = Field(description="ticks logged; while the run goes, the live count")
    stats: RunStats
    has_report: bool
    description: str = Field(
        description="the test and its parameters in words and units (mm, Hz, s, on/off)"
    )
    progress: RunProgress | None = Field(
        None, description="while the run goes: how far it is; null otherwise"
    )


class CompareRow(_Out):
    label: str = Field(description="the figure, e.g. 'RMSE x'")
    unit: str = Field(description="the values' unit (mm, %, Hz, ms, ticks) or '' for text")
    values: list[float | str | None] = Field(description="one per run, in the order asked")


class CompareOut(_Out):
    """Runs side by side: their records, a table of their figures, the overlay plot."""

    ids: list[str]
    runs: list[RunOut]
    rows: list[CompareRow]
    plot: str = Field(description="the errors overlaid: GET this PNG (same ids)")


class RunStarted(_Out):
    run_id: str


class WindowStats(_Out):
    tracking: ErrorStats
    start_s: float | None
    end_s: float | None


LeaseOut = model_of(
    LeaseView,
    "LeaseOut",
    base=_Out,
    doc="The public view of the control lease: never anything that lets a client act for "
    "the holder (the lease id is only in the answer to the POST that took it).",
    describe={
        "held": "someone holds control now (the lease has not lapsed)",
        "holder": "the holder's display name (a label, not authority)",
        "since_s": "when control was taken [s, Unix time]",
        "idle_s": "seconds since the holder's last command [s]",
    },
)


class LeaseTaken(_Out):
    """Control taken: send ``lease_id`` as ``X-Lease`` with every command."""

    lease_id: str = Field(description="the secret lease id; only its holder knows it")
    holder: str = Field(description="the display name given")
    timeout_s: float = Field(description="the lease lapses after this long without a command")
    took_over_from: LeaseOut | None = Field(  # type: ignore[valid-type]
        None, description="the lease this one replaced, when someone held control; else null"
    )


class PoseAccepted(_Out):
    accepted: bool = Field(description="false for out-of-order, duplicate or jumping samples")
    input: PoseInputStatus


class WristInfo(_Out):
    """The wrist ([wrist] section): whether one is fitted and its limits [rad]."""

    enabled: bool
    min_rad: float | None = Field(description="lowest wrist angle [rad]; null without a wrist")
    max_rad: float | None = Field(description="highest wrist angle [rad]; null without a wrist")


class RobotModelOut(_Out):
    """The robot model the controller uses (app/control/model.py): symmetric (one L, l,
    R, r), per-leg (a geometry calibration's) or linear; each leg's lengths [m]."""

    kind: str = Field(description="symmetric, per-leg or linear")
    version: int = Field(description="0: the config's model; +1 per geometry applied since")
    origin: str = Field(description="config, or the calibration run it came from")
    L_m: list[float] | None = None
    l_m: list[float] | None = None
    R_m: list[float] | None = None
    r_m: list[float] | None = None
    angles_rad: list[float] | None = Field(
        None, description="each leg's base direction about z [rad] (0, 120, 240 deg nominal)"
    )


class InfoOut(_Out):
    """Facts the dashboard cannot read from status."""

    viser_port: int | None
    estop_port: int | None = Field(
        description="the robot node's e-stop listener's port (POST /estop there stops, as "
        "/api/estop does, without passing through this server); null: not running"
    )
    estop_host: str | None = Field(
        description="its host, for a robot node on another machine; null: this page's host"
    )
    token_required: bool
    telemetry_hz: float
    jog_max_velocity_m_s: float
    jog_step_m: float
    confirm_move_m: float
    home_m: list[float]
    joint_speed_limit_rad_s: float
    loop_rate_hz: float
    tool_offset_m: list[float] = Field(
        description="the tool tip in the platform frame at phi = 0 [m] ([tool] offset_m; "
        "zeros without a tool: the tip is the platform centre)"
    )
    wrist: WristInfo
    robot: RobotModelOut = Field(
        description="the robot model the controller uses now (a geometry calibration's "
        "apply changes it)"
    )


class WorkspaceSectionOut(_Out):
    """GET /api/workspace/section: where the gate accepts a goal on one plane.

    Row j of ``reachable`` is v = v_m[j], its character i is u = u_m[i]: '1' where
    (u, v) at the level passes the gate's workspace check (margin, ceiling).
    """

    plane: str = Field(description="xy | xz | yz")
    at_m: float = Field(description="the level used, rounded to 1 mm [m]")
    phi_rad: float = Field(0.0, description="the wrist angle used, rounded to 1 deg [rad]")
    axes: list[str] = Field(description="the names of u, v and the level's axis, e.g. x, y, z")
    u_m: list[float] = Field(description="cell centres along u [m]")
    v_m: list[float] = Field(description="cell centres along v [m]")
    reachable: list[str] = Field(description="one string per v, '1'/'0' per u")
    margin_m: float = Field(description="the gate's distance from the boundary [m]")
    z_max_m: float = Field(description="the gate's ceiling [m]")


class NearestOut(_Out):
    """GET /api/workspace/nearest: the point, whether the gate's workspace holds it, and
    the nearest point it holds (the point itself when inside) [m]."""

    position_m: list[float]
    inside: bool
    nearest_m: list[float]
    distance_m: float

"""What the control loop publishes each tick: faults and an immutable snapshot."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from app.control.timing import TimingStats
from hardware.bus import READINGS, BusStats, PositionGains

_NAN3 = np.full(3, np.nan)
_NO_TIMING = TimingStats(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0)


def unread(count: int = 3) -> dict[str, np.ndarray]:
    """Every servo reading (hardware/bus.py READINGS) unknown: NaN, shape (count,)."""
    return {name: np.full(count, np.nan) for name in READINGS}


@dataclass(frozen=True)
class RobotInfo:
    """What a loop's snapshots say of the robot that does not change while it runs: the
    backend's name (``sim``, ``emulated``, ``dynamixel``, ...) and description, the legs'
    servo ids in joint order, and ``boot``, this loop's own id (a robot node started again
    has another: a station then knows its snapshots are a new loop's)."""

    backend: str = ""
    backend_description: str = ""
    servo_ids: tuple[int, ...] = (1, 2, 3)
    boot: str = ""
    wrist_servo_id: int | None = None  # the wrist's servo on the legs' bus (None: no wrist)


@dataclass(frozen=True)
class Fault:
    """Why the robot stopped: ``source`` is bus, servo, following, source, gate or loop.

    One cause is recorded once (see :meth:`cause`) however often it recurs: ``count`` times
    seen, first / last seen at ``first_time_s`` / ``last_time_s`` [s, loop time];
    ``time_s`` is the first time (kept for older clients); ``reason`` is the latest text.
    ``kind`` is the stable part of the cause (e.g. "reads failed" while the text counts
    the reads); empty means the reason itself is the cause.
    """

    source: str
    reason: str
    servo_id: int | None = None
    time_s: float = 0.0
    kind: str = ""
    count: int = 1
    last_time_s: float | None = None  # None: same as time_s (seen once)

    @property
    def cause(self) -> tuple[str, int | None, str]:
        """What makes two faults the same: source, servo and kind (else the reason)."""
        return (self.source, self.servo_id, self.kind or self.reason)

    @property
    def first_time_s(self) -> float:
        return self.time_s

    def again(self, later: Fault) -> Fault:
        """This cause seen once more, as ``later`` reports it (its text, its time)."""
        return replace(self, reason=later.reason, count=self.count + 1, last_time_s=later.time_s)

    def as_dict(self) -> dict:
        return {
            "source": self.source,
            "kind": self.kind or self.reason,
            "reason": self.reason,
            "servo_id": self.servo_id,
            "time_s": self.time_s,
            "count": self.count,
            "first_time_s": self.time_s,
            "last_time_s": self.time_s if self.last_time_s is None else self.last_time_s,
        }


@dataclass(frozen=True)
class WristReading:
    """The wrist's servo at the last read: phi [rad] (calibrated, 0 = the tool's heading
    at assembly, + as its direction says), its speed [rad/s], current [A], temperature
    [degC] and the names of its latched hardware errors (empty if none)."""

    position_rad: float
    velocity_rad_s: float
    current_a: float
    temperature_c: float
    hardware_errors: tuple[str, ...]
    torque_enabled: bool | None = None
    voltage_v: float = float("nan")  # input voltage [V]
    pwm: float = float("nan")  # PWM duty cycle, signed (1 = full)


@dataclass(frozen=True)
class ContactReading:
    """The tip's contact force as the loop estimates it each tick (app/control/contact.py).

    force_n: the force the tip applies on what it touches, base frame [N], (3,) (NaN when
    not known); std_n: its 1-sigma uncertainty per axis [N], (3,); valid: the estimate
    could be made this tick (every leg's current read, the Jacobian usable); reason: why
    not, when it could not (None otherwise); fresh: the read was news (False: a simulator
    that did not step since the last read; a touch and a press then wait, commanding
    nothing new from an old force).
    """

    force_n: np.ndarray = field(default_factory=lambda: _NAN3)
    std_n: np.ndarray = field(default_factory=lambda: _NAN3)
    valid: bool = False
    reason: str | None = "not estimated"
    fresh: bool = True  # the read it came from was news (a lagging simulator's is not)

    @property
    def magnitude_n(self) -> float:
        """|force_n| [N] (NaN when not known)."""
        return float(np.linalg.norm(self.force_n))


@dataclass(frozen=True)
class TouchResult:
    """How a touch (app/control/touch.py) ended. outcome: "contact" (stopped at the set
    force), "no contact" (its travel ended first) or "stopped" (a fault, a stop, e-stop);
    contact_point_m: where the surface is along the touch's direction, base frame [m]
    (the tip where the force, extrapolated along its rise, is zero; NaN without contact);
    force_n: the contact force it stood at (before a retract) [N] (3,); peak_force_n: the
    largest force along the direction seen [N]; travel_m: the furthest the command went
    along it [m]; reason: why it was "stopped" (None otherwise); direction: the
    unit direction moved along (3,); source_id: the touch's id; joints_at_contact_rad: the
    legs' joints as read at the tick contact was seen (3,) [rad] (NaN without contact): a
    probe calibration's touch (the contact point itself comes from the model)."""

    outcome: str
    contact_point_m: np.ndarray
    force_n: np.ndarray
    peak_force_n: float
    travel_m: float
    direction: np.ndarray
    source_id: str | None = None
    joints_at_contact_rad: np.ndarray = field(default_factory=lambda: _NAN3)
    reason: str | None = None  # why a touch was "stopped" (the fault, the command)


@dataclass(frozen=True)
class FeedState:
    """How a path plays (app/link/paths.py ``Playback``): ``rate`` its time's rate now
    (0: standing, 1: as planned), ``override`` the feed override set (0.1 to 1.0: the
    program was checked at 100 % feed), ``paused`` why it stands or is stopping (None:
    running), ``time_left_s`` the path time left at the override [s], ``optional_stop``
    whether M1 stops, ``stop_line`` the program line it stops at (None: none)."""

    rate: float = 1.0
    override: float = 1.0
    paused: str | None = None
    time_left_s: float = 0.0
    optional_stop: bool = False
    stop_line: int | None = None


@dataclass(frozen=True)
class Snapshot:
    """The loop's state after one tick, in SI units and the base frame.

    Arrays are shape (3,); NaN where unknown (no successful read yet, FK failed). Points
    (``point_*_m``, ``goal_m``, ``external_m``) are the tool tip; ``platform_measured_m``
    is the platform centre (the same without a tool) and ``phi_rad`` the wrist angle [rad].

    How the tick started (app/control/timing.py ``TickTiming``): lateness_ms after its
    deadline, gap_ms since the previous tick started, overrun (it missed its deadline).
    How fresh the feedback was (app/control/safety.py ``FeedbackFreshness``): sim_time_s,
    the simulated time of the state read (NaN on real servos); stale, the read brought no
    news; feedback_age_ms, loop time since the last fresh read (0 when fresh).
    """

    time_s: float = 0.0
    tick: int = 0
    mode: str = "idle"
    torque: bool = False
    estopped: bool = False
    faults: tuple[Fault, ...] = ()
    faults_dropped: int = 0  # older causes no longer in ``faults``
    warning: str | None = None
    notice: str | None = None  # about the last motion command, e.g. where it started from
    joints_measured_rad: np.ndarray = field(default_factory=lambda: _NAN3)
    point_measured_m: np.ndarray = field(default_factory=lambda: _NAN3)
    platform_measured_m: np.ndarray = field(default_factory=lambda: _NAN3)
    phi_rad: float = 0.0
    joints_commanded_rad: np.ndarray = field(default_factory=lambda: _NAN3)
    point_commanded_m: np.ndarray = field(default_factory=lambda: _NAN3)
    goal_m: np.ndarray = field(default_factory=lambda: _NAN3)
    # where a new path starts (commands.start_point's rule): what a plan must start from
    start_m: np.ndarray = field(default_factory=lambda: _NAN3)
    # the servo readings by name (hardware/bus.py READINGS: velocity, current, ...), (3,)
    readings: Mapping[str, np.ndarray] = field(default_factory=lambda: unread())
    moving: tuple[bool, ...] = (False, False, False)
    hardware_errors: tuple[tuple[str, ...], ...] = ((), (), ())
    # per leg servo, its Torque Enable as read from it (None: not known); ``torque`` is
    # the torque asked for and held: False once any servo reads it off (a shutdown)
    torque_enabled: tuple[bool | None, ...] = (None, None, None)
    missed_reads: int = 0
    phase: str = ""
    lateness_ms: float = 0.0
    extra: dict | None = None
    external_m: np.ndarray = field(default_factory=lambda: _NAN3)  # e.g. motion capture
    gap_ms: float = 0.0
    overrun: bool = False
    sim_time_s: float = float("nan")
    stale: bool = False
    feedback_age_ms: float = 0.0
    # the wrist (app/control/wrist.py), NaN without one: phi [rad] as read, as last
    # written, and its goal (NaN: holding where it is commanded)
    phi_measured_rad: float = float("nan")
    phi_commanded_rad: float = float("nan")
    phi_goal_rad: float = float("nan")
    # the wrist's servo at the last read (its current, temperature, errors): None without
    # a wrist or before its first read
    wrist_servo: WristReading | None = None
    # what GET /api/status reports beside the tick's own figures, as of this tick: the
    # robot (static), the legs' position gains in use (joint order), the loop's timing
    # since start and over its last 10 s (app/control/timing.py; the figures of the
    # ticks before this one), and the bus's transaction counters
    info: RobotInfo = field(default_factory=RobotInfo)
    gains: tuple[PositionGains, ...] = ()
    # the legs' servos' operating mode ("position" | "current_based_position") and Goal
    # Current per leg [A] (joint order), as last written (app/control/servo_current.py)
    servo_mode: str = "position"
    goal_current_a: tuple[float, ...] = ()
    loop_total: TimingStats = _NO_TIMING
    loop_window: TimingStats = _NO_TIMING
    bus_stats: BusStats = field(default_factory=BusStats)
    # the active goal source as a station follows it over the link (app/link/): its id
    # (None: none, or one with no id), its time [s] and a program's line being executed;
    # and the id of the last source that ran to its end (not stopped, faulted or replaced)
    source_id: str | None = None
    source_t_s: float | None = None
    source_line: int | None = None
    # a path's playback (app/link/paths.py Playback): feed override, pause, time left
    source_feed: FeedState | None = None
    finished_source_id: str | None = None
    # the tip's contact force estimated this tick (app/control/contact.py), and how the
    # last touch ended (None: none since the loop started)
    contact: ContactReading = field(default_factory=ContactReading)
    touch: TouchResult | None = None

    @property
    def velocity_rad_s(self) -> np.ndarray:
        """The joints' velocity as read [rad/s], (3,) (a reading: ``readings``)."""
        return self.readings["velocity_rad_s"]

    @property
    def tracking_error_m(self) -> np.ndarray:
        """Commanded minus measured tip position [m]."""
        return self.point_commanded_m - self.point_measured_m

    @property
    def has_setpoint(self) -> bool:
        """The loop holds the arm to a setpoint: torque on, no e-stop, no fault, a goal."""
        return (
            self.torque
            and not self.estopped
            and not self.faults
            and bool(np.all(np.isfinite(self.goal_m)))
        )

    @property
    def tool_phi_rad(self) -> float:
        """The wrist angle the tool is at [rad]: the wrist servo's reading, else (no wrist)
        the angle the loop holds the tool at (``phi_rad``, the tip's goals' angle)."""
        return self.phi_measured_rad if math.isfinite(self.phi_measured_rad) else self.phi_rad

    @property
    def shown_error_m(self) -> np.ndarray:
        """The tracking error an operator is shown [m], (3,): NaN (unknown) without a
        setpoint, where commanded minus measured is a stale figure (e.g. a relaxed arm
        falling away from the last command after torque off)."""
        return self.tracking_error_m if self.has_setpoint else np.full(3, np.nan)

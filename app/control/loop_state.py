"""The control loop's mutable state: one record, owned by the control thread alone.

The tick (app/control/controller.py) and the operator commands (app/control/commands.py)
are functions that take this record and change it; no other thread reads it. What other
threads see is the immutable :class:`~app.control.state.Snapshot` made from it each tick.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from app.config import SafetySettings
from app.control.contact import NOT_ESTIMATED, ContactMonitor
from app.control.gravity import GravityOffset
from app.control.safety import FeedbackFreshness, FollowingError, MissCounter
from app.control.sources import GoalSource
from app.control.state import (
    ContactReading,
    Fault,
    RobotInfo,
    Snapshot,
    TouchResult,
    WristReading,
    unread,
)
from app.control.timing import TickTiming, TimingRecorder
from hardware.bus import BusStats, JointState, PositionGains


def _nan3() -> np.ndarray:
    return np.full(3, np.nan)


@dataclass
class LoopState:
    """Everything the loop remembers between ticks; arrays are (3,), NaN where unknown.

    Points are the tool tip (base frame, app/control/gate.py), the platform centre plus the
    tool offset turned by ``phi_rad``; with no tool they are the platform centre.
    joints: the last successful read; platform_m: FK of it (the measured platform centre);
    point_m: the tool tip there; commanded_rad / commanded_point_m: the last goal written
    to the servos and its tip (None / NaN before any); goal_m: the tip setpoint the loop is
    using (a jog target, a move's end, a run's nominal point, the held point after a stop;
    NaN with torque off); phi_rad: the wrist angle the loop holds the tool at [rad] (0
    without a wrist: the one place a goal's phi goes, and each tick converts its tip
    setpoint to the platform with it); external_m: the simulator's own measurement at the
    last read, as a tip.
    resync: the command is stale (torque off, e-stop or a fault since the last motion, or
    none yet): the next motion starts from the measured position and ``notice`` says so.
    phi_goal_rad: the wrist's goal [rad] (None: it holds where it is commanded);
    phi_commanded_rad: the wrist goal last written (None: none, or no wrist); wrist: the
    wrist's servo at the last read (app/control/wrist.py), None without a wrist.
    settle_rad: a finished source's last joints [rad] that the speed limit kept the
        command short of (late ticks: the source advanced further than the limit let the
        joints follow); the loop steps on to them, then clears it. None otherwise.
    hold_deadline_s: while an operator holds a jog (app/control/held_jog.py), the loop
    time [s] after which it stops unless a heartbeat renews it; None otherwise.
    gains: the legs' position gains in use (joint order; the factory's until written);
    gravity: the servo goals' shift by the predicted sag (app/control/gravity.py), None
    when gravity compensation is off; recorder: every tick's timing (its figures go out
    in the snapshot); info: the robot as the snapshots name it.
    """

    misses: MissCounter
    following: FollowingError
    source: GoalSource | None = None
    torque: bool = False
    estopped: bool = False
    faults: list[Fault] = field(default_factory=list)
    faults_dropped: int = 0  # causes dropped from the front of ``faults`` (bounded list)
    warning: str | None = None
    notice: str | None = None  # about the last motion command (e.g. where it started from)
    resync: bool = True
    hold_deadline_s: float | None = None
    freshness: FeedbackFreshness = field(default_factory=lambda: FeedbackFreshness(0.5))
    hold_velocity_m_s: np.ndarray | None = None  # the held jog's velocity [m/s]
    joints: JointState | None = None
    point_m: np.ndarray = field(default_factory=_nan3)
    platform_m: np.ndarray = field(default_factory=_nan3)
    phi_rad: float = 0.0
    commanded_rad: np.ndarray | None = None
    commanded_point_m: np.ndarray = field(default_factory=_nan3)
    goal_m: np.ndarray = field(default_factory=_nan3)
    external_m: np.ndarray = field(default_factory=_nan3)
    tick: int = 0
    phase: str = ""
    extra: dict | None = None
    dt_s: float = 0.0  # scheduled time since the previous tick (sources advance by it)
    lateness_s: float = 0.0
    timing: TickTiming = field(default_factory=TickTiming)  # how this tick started
    phi_goal_rad: float | None = None
    phi_commanded_rad: float | None = None
    wrist: WristReading | None = None
    settle_rad: np.ndarray | None = None
    gains: tuple[PositionGains, ...] = (PositionGains(),) * 3
    servo_mode: str = "position"  # the legs' operating mode (app/control/servo_current.py)
    goal_current_a: tuple[float, ...] = ()  # their Goal Current [A] as last written
    gravity: GravityOffset | None = None
    recorder: TimingRecorder = field(default_factory=lambda: TimingRecorder(200.0))
    info: RobotInfo = field(default_factory=RobotInfo)
    finished_source_id: str | None = None  # the last source (with an id) that ran to its end
    # the tip's contact force: the monitor that estimates and checks it each tick (None: no
    # estimate), this tick's reading, and the last touch's result (app/control/contact.py)
    contact_monitor: ContactMonitor | None = None
    contact: ContactReading = NOT_ESTIMATED
    touch: TouchResult | None = None

    @classmethod
    def initial(
        cls, safety: SafetySettings, period_s: float, info: RobotInfo | None = None
    ) -> LoopState:
        """The state before the first read: torque off, no source, no faults, the factory's
        gains; ``info`` names the robot in the snapshots (None: a nameless one)."""
        return cls(
            MissCounter(safety.max_missed_reads),
            FollowingError(safety.following_error_rad, safety.following_error_time_s),
            freshness=FeedbackFreshness(safety.stale_feedback_s),
            dt_s=period_s,
            recorder=TimingRecorder(1.0 / period_s),
            info=info or RobotInfo(),
        )

    @property
    def mode(self) -> str:
        if self.estopped:
            return "estop"
        if self.faults:
            return "fault"
        return self.source.name if self.source is not None else "idle"

    @property
    def reference_rad(self) -> np.ndarray:
        """The joints the next command starts from: the commanded ones, else the measured."""
        if self.commanded_rad is not None:
            return self.commanded_rad
        if self.joints is None:  # commands check for this first; the tick never asks then
            raise RuntimeError("no joint state read yet")
        return self.joints.position_rad

    @property
    def start_m(self) -> np.ndarray:
        """Where a new path starts (3,) [m]: the commanded point, else (first motion after
        torque off, e-stop or a fault, or nothing commanded yet) the measured one."""
        if not self.resync and np.isfinite(self.commanded_point_m).all():
            return self.commanded_point_m
        return self.point_m

    def snapshot(self, time_s: float, bus_stats: BusStats | None = None) -> Snapshot:
        """The immutable record other threads read, as of now; ``bus_stats``: the bus's
        counters now (None: none known)."""
        state = self.joints
        nan3 = _nan3()
        commanded = self.commanded_rad if self.commanded_rad is not None else nan3
        return Snapshot(
            time_s=time_s,
            tick=self.tick,
            start_m=self.start_m.copy(),
            mode=self.mode,
            torque=self.torque and self._servos_hold(),
            estopped=self.estopped,
            faults=tuple(self.faults),
            faults_dropped=self.faults_dropped,
            warning=self.warning,
            notice=self.notice,
            joints_measured_rad=state.position_rad if state else nan3,
            point_measured_m=self.point_m,
            platform_measured_m=self.platform_m,
            phi_rad=self.phi_rad,
            joints_commanded_rad=commanded,
            point_commanded_m=self.commanded_point_m,
            goal_m=self.goal_m,
            readings=state.readings() if state else unread(),
            moving=tuple(bool(m) for m in state.moving) if state else (False,) * 3,
            hardware_errors=state.hardware_errors if state else ((),) * 3,
            torque_enabled=_torque_read(state),
            missed_reads=self.misses.total,
            phase=self.phase if self.source else "",
            lateness_ms=self.lateness_s * 1e3,
            extra=self.extra if self.source else None,
            external_m=self.external_m,
            gap_ms=self.timing.gap_s * 1e3,
            overrun=self.timing.overrun,
            sim_time_s=_sim_time(state),
            stale=self.freshness.stale,
            feedback_age_ms=self.freshness.age_s * 1e3,
            phi_measured_rad=_or_nan(self.wrist.position_rad if self.wrist else None),
            phi_commanded_rad=_or_nan(self.phi_commanded_rad),
            phi_goal_rad=_or_nan(self.phi_goal_rad),
            wrist_servo=self.wrist,
            info=self.info,
            gains=self.gains,
            servo_mode=self.servo_mode,
            goal_current_a=self.goal_current_a,
            loop_total=self.recorder.since_start(),
            loop_window=self.recorder.last_window(),
            bus_stats=bus_stats or BusStats(),
            source_id=getattr(self.source, "source_id", None),
            source_t_s=getattr(self.source, "t_s", None),
            source_line=getattr(self.source, "program_line", None),
            source_feed=getattr(self.source, "feed_state", None),
            finished_source_id=self.finished_source_id,
            contact=self.contact,
            touch=self._touch(),
        )

    def _touch(self) -> TouchResult | None:
        """The last touch's result; one still "touching" whose source no longer runs (a
        fault, a stop, an e-stop took it) reads "stopped"."""
        touch = self.touch
        if touch is None or touch.outcome != "touching":
            return touch
        if getattr(self.source, "source_id", None) == touch.source_id and self.source is not None:
            return touch
        if self.estopped:
            why = "e-stop"
        elif self.faults:
            why = f"fault: {self.faults[-1].reason}"
        else:  # a stop, another motion, torque off, a lost link (the notice says which)
            why = self.notice or "stopped by a command (a stop, another motion, torque off)"
        self.touch = replace(touch, outcome="stopped", reason=why)
        return self.touch

    def _servos_hold(self) -> bool:
        """No servo (legs, wrist) reads its Torque Enable off at the last read: one whose
        Shutdown dropped it (an overload) does not hold the arm, whatever was asked.
        Servos whose bus does not say count as holding."""
        read = [*_torque_read(self.joints), self.wrist.torque_enabled if self.wrist else None]
        return False not in read


def _torque_read(state: JointState | None) -> tuple[bool | None, ...]:
    """Each leg servo's Torque Enable as read (None: not known)."""
    if state is None or state.torque_enabled is None:
        return (None,) * 3
    return tuple(state.torque_enabled)


def _or_nan(value: float | None) -> float:
    return float("nan") if value is None else value


def _sim_time(state: JointState | None) -> float:
    return float("nan") if state is None or state.sim_time_s is None else state.sim_time_s

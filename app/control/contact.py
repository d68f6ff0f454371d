"""Contact in the loop: the tip's force each tick, and the limits no motion may pass.

Each tick after the read, :class:`ContactMonitor` turns the servos' currents into the
tip's contact force (app/control/force.py: the currents' torques minus the model's
gravity and dynamics of thesis ch. 3.2, through the Jacobian's transpose) and checks it:

- a source that presses on purpose (a touch, a press: ``presses = True``) faults when the
  force along any axis passes ``contact.force_limit_n``, or when the estimate is lost (a
  current not read): it cannot know what it pushes;
- with ``contact.collision_stop`` (force-limited motion), any motion faults when the force
  passes ``contact.collision_force_n`` ("collision", with the force and the point);
- a fault of either kind stops the motion, and the joints are commanded where they were
  measured at that tick, so the servos stop pushing further into what was hit.

A source that wants the force (``observe_contact``) is handed this tick's reading before
it gives its setpoint (app/control/tick.py).

Transitions (docs/contact.md): moving -> fault "collision" | "force limit" | "force
estimate lost" -> (reset) idle; the fault holds the arm where it was measured.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from app.config import ContactSettings
from app.control.state import ContactReading, Fault
from hardware.bus import JointState

NOT_ESTIMATED = ContactReading()


class Estimator(Protocol):
    """What turns a read into a force (app/control/force.py ``ForceEstimator``)."""

    def estimate(self, joints: JointState, gravity: Any = ..., qdd: Any = None) -> Any: ...


@dataclass
class ContactMonitor:
    """The loop's force estimate and its limits (module doc).

    estimator: the force estimator (None: no estimate; readings stay "not estimated");
    settings: the ``[contact]`` section; gravity: gravity in the base frame [m/s^2] (3,)
    (a tilted drone turns it; app/world sets it when it knows the drone's attitude).
    """

    estimator: Estimator | None
    settings: ContactSettings
    gravity: np.ndarray | None = None

    def read(self, joints: JointState | None, qdd: np.ndarray | None = None) -> ContactReading:
        """This tick's reading from ``joints`` (the legs' read), ``qdd`` the joints'
        acceleration [rad/s^2] (3,) when known (None: taken as zero)."""
        if self.estimator is None:
            return ContactReading(reason="no force estimate on this robot")
        if joints is None:
            return ContactReading(reason="no joint state read")
        kwargs: dict[str, Any] = {"qdd": qdd}
        if self.gravity is not None:
            kwargs["gravity"] = self.gravity
        try:
            got = self.estimator.estimate(joints, **kwargs)
        except ValueError as exc:  # a state the model cannot take: no estimate this tick
            return ContactReading(reason=str(exc))
        force = np.asarray(got.force_n, dtype=float)
        std = np.asarray(got.std_n, dtype=float)
        valid = bool(got.valid) and bool(np.isfinite(force).all())
        reason = None if valid else (got.reason or "the force is not finite")
        return ContactReading(force, std, valid, reason)

    def check(
        self, reading: ContactReading, source: Any, point_m: np.ndarray, time_s: float
    ) -> Fault | None:
        """The fault this tick's ``reading`` makes while ``source`` runs (None: none).

        ``point_m`` is the measured tip (3,) [m], named in the fault."""
        if source is None:
            return None
        presses = bool(getattr(source, "presses", False))
        limited = presses or self.settings.collision_stop
        if not limited:
            return None
        if not reading.valid:
            why = reading.reason or "unknown"
            return Fault("contact", f"force estimate lost: {why}", time_s=time_s, kind="estimate")
        force = reading.force_n
        size = reading.magnitude_n
        where = _mm(point_m)
        if presses and size > self.settings.force_limit_n:
            return Fault(
                "contact",
                f"force {size:.1f} N past the limit of {self.settings.force_limit_n:g} N "
                f"(contact.force_limit_n) at {where}, force {_newtons(force)}: stopped",
                time_s=time_s,
                kind="force limit",
            )
        if self.settings.collision_stop and not presses and size > self.settings.collision_force_n:
            return Fault(
                "contact",
                f"collision: {size:.1f} N at {where}, force {_newtons(force)} "
                f"(contact.collision_force_n {self.settings.collision_force_n:g} N): stopped",
                time_s=time_s,
                kind="collision",
            )
        return None


def _mm(point_m: np.ndarray) -> str:
    if not np.isfinite(point_m).all():
        return "an unknown point"
    return "(" + ", ".join(f"{v * 1e3:.1f}" for v in point_m) + ") mm"


def _newtons(force: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.2f}" for v in force) + ") N"


def observe(
    source: Any, reading: ContactReading, point_m: np.ndarray, joints_rad: np.ndarray
) -> None:
    """Hand ``source`` this tick's reading, the measured tip (3,) [m] and the legs' joints
    as read (3,) [rad], when it wants them."""
    observer: Callable[..., None] | None = getattr(source, "observe_contact", None)
    if observer is not None:
        observer(reading, point_m, joints_rad)

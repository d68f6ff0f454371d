"""Who arms the robot node's ROS goal input: one operator's lease, for as long as it holds.

The node takes goals from its ROS goal topic only while armed (app/robot/ros.py), and it
disarms itself whenever its link is taken, handed back or lost. The station adds the
operator: ``PUT /api/ros2/goals`` arms it for the lease that asked, and a watcher here
disarms it as soon as that lease is given back, lapses or changes hands, or a procedure
or a run holds the robot (the station's motion owner, which the node cannot see: a ROS
goal must not move the robot under a calibration). Arming again is the operator's act.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from app.control.authority import Authority
from app.control.errors import MotionRefused

log = logging.getLogger(__name__)
WATCH_S = 0.1  # how often the watcher looks at the lease and the motion owner


class RosGoalArming:
    """Arms and watches the ROS goal input of ``controller``'s robot node (a RobotClient)."""

    def __init__(self, authority: Authority, controller: Any) -> None:
        self.authority, self.controller = authority, controller
        self._lease: str | None = None
        self.disarmed_because: str | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        # a procedure disarms them as it claims the robot, before its first motion
        controller.owner.add_claim_listener(self._on_claim)
        self._thread = threading.Thread(target=self._watch, name="ros2-arming", daemon=True)
        self._thread.start()

    def _on_claim(self, claim: Any) -> None:
        if self._lease is not None:
            self.disarm(f"the robot is busy: {claim.what} started")

    def arm(self, lease_id: str) -> Any:
        """Arm for ``lease_id``: a Future of the node's answer. MotionRefused while a
        procedure or a run holds the robot."""
        why = self.controller.owner.busy()
        if why is not None:
            raise MotionRefused(f"ROS goals cannot be armed now: {why}")
        with self._lock:
            self._lease, self.disarmed_because = lease_id, None
        return self.controller.request("ros_goals", {"enabled": True})

    def disarm(self, because: str) -> Any:
        """Disarm (a Future of the node's answer), saying why."""
        with self._lock:
            self._lease, self.disarmed_because = None, because
        return self.controller.request("ros_goals", {"enabled": False})

    def _reason(self) -> str | None:
        lease = self._lease
        if lease is None:
            return None
        if not self.authority.active(lease):
            return "the lease that armed them was given back, lapsed or taken over"
        why = self.controller.owner.busy()
        return None if why is None else f"the robot is busy: {why}"

    def _watch(self) -> None:
        while not self._stop.wait(WATCH_S):
            try:
                why = self._reason()
                if why is not None:
                    log.warning("ROS goals disarmed: %s", why)
                    self.disarm(why)
            except Exception:  # noqa: BLE001 - the watcher must outlive a failed request
                log.exception("ros2 arming watch")

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

"""Why a command to the controller was refused; the server maps these to HTTP codes.

``GoalRejected``: the goal itself is bad (HTTP 422); ``MotionRefused``: the robot is not in a
state to move now (HTTP 409). Kept apart from the gate and the commands so the server, the
runs manager and the scene can catch them without importing either.
"""

from __future__ import annotations

import numpy as np


class GoalRejected(ValueError):
    """A goal failed the gate; ``nearest`` is the closest acceptable point when known.

    ``goal`` (3,) [m] is the refused point when a point the gate takes near it can be
    offered (the server computes one that passes every check: app/server/sections.py
    ``nearest``), at the wrist angle ``phi`` [rad] the goal was asked at; ``reason`` is the
    message without the nearest point.
    """

    def __init__(
        self,
        reason: str,
        nearest: np.ndarray | None = None,
        goal: np.ndarray | None = None,
        phi: float = 0.0,
    ) -> None:
        self.reason = reason
        self.phi = phi
        if nearest is not None:
            mm = ", ".join(f"{v:.4f}" for v in nearest)
            reason = f"{reason}; nearest reachable point [{mm}] m"
        super().__init__(reason)
        self.nearest = nearest
        self.goal = goal


class MotionRefused(RuntimeError):
    """The robot cannot move now (e-stop, fault or torque off); the message says which."""

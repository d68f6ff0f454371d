"""The one gate every goal passes before it can reach a servo (like Klipper's check_move).

Goals are tool tips (base frame) at a wrist angle phi [rad]; the gate checks the platform
centre each tip implies, ``tool.platform(tip, phi)`` (kinematics/tool.py), and gives its
answers (the nearest point, clamped points) back as tips. With no tool (a zero offset) the
tip is the platform centre.

Order of checks: finite -> wrist angle (none without a wrist) -> the implied platform
point inside the workspace with margin and below the ceiling ->
IK on the branch nearest the current joints -> joint limits -> distance from singularity.
REST goals that fail are refused with the reason (and the nearest reachable point when
the workspace is the problem); jog goals are clamped onto the workspace instead. Joint
speed is limited per tick, so even a gated goal reaches the servos gradually.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.control.errors import GoalRejected
from kinematics import DeltaError, LinearDelta, PerLegRotaryDelta, RotaryDelta, Tool

FAR_M = 10.0  # goals beyond this are scaled back before projecting (still refused)


@dataclass(frozen=True)
class Gate:
    """Checks and limits for one robot; pure (no state), safe from any thread.

    joint_min_rad / joint_max_rad: per-joint limits, shape (3,); margin_m: distance kept
    from the workspace boundary; z_max_m: ceiling for the platform; min_dexterity: lowest
    1/cond(J) accepted; max_step_rad: largest joint change per tick (speed * period).
    wrist_min_rad / wrist_max_rad: the wrist's limits [rad] (None: no wrist, phi stays 0);
    wrist_max_step_rad: largest wrist change per tick [rad] (its speed * period).
    tool: the tool whose tip the goals are (the platform centre by default).
    robot: a symmetric rotary or linear Delta, or a rotary one whose legs each have their
    own geometry (a geometry calibration's, app/control/model.py).

    Points in and out are tool tips (3,) [m] in the base frame, at wrist angle ``phi``
    [rad] (0 without a wrist); the workspace, ceiling and IK apply to the platform centre.
    """

    robot: RotaryDelta | PerLegRotaryDelta | LinearDelta
    joint_min_rad: tuple[float, float, float]
    joint_max_rad: tuple[float, float, float]
    margin_m: float
    z_max_m: float
    min_dexterity: float
    max_step_rad: float
    wrist_min_rad: float | None = None
    wrist_max_rad: float | None = None
    wrist_max_step_rad: float = 0.0
    tool: Tool = field(default_factory=Tool)

    def platform(self, tip: Any, phi: Any = 0.0) -> np.ndarray:
        """The platform centre (*, 3) [m] that puts the tool tip at ``tip`` (*, 3) [m]."""
        return self.tool.platform(tip, phi)

    def tip(self, platform: Any, phi: Any = 0.0) -> np.ndarray:
        """The tool tip (*, 3) [m] of the platform centre ``platform`` (*, 3) [m]."""
        return self.tool.tip(platform, phi)

    def __post_init__(self) -> None:
        # The first projection for a (robot, margin, ceiling) computes the workspace's edges
        # (tens to hundreds of ms, then cached): pay it here, not in the first jog's tick.
        with contextlib.suppress(DeltaError):
            self.robot.project((0.0, 0.0, FAR_M), margin=self.margin_m, z_max=self.z_max_m)

    def inside(self, point: np.ndarray, phi: float = 0.0) -> bool:
        """The platform point the tip ``point`` implies is within the workspace margin and
        below the ceiling."""
        platform = self.platform(point, phi)
        if not platform[2] <= self.z_max_m:
            return False
        return bool(self.robot.reachable(platform, margin=self.margin_m))

    def nearest(self, point: np.ndarray, phi: float = 0.0) -> np.ndarray:
        """The closest tip that passes :meth:`inside` (``point`` itself if it does).

        The tool offset is a translation at a given phi, so the closest tip is the tip of
        the platform point closest to the one ``point`` implies."""
        platform = self.platform(point, phi)
        largest = float(np.abs(platform).max())
        if largest > FAR_M:  # same direction, without squaring 1e300
            direction = platform / largest
            platform = direction * (FAR_M / float(np.linalg.norm(direction)))
        found = self.robot.project(platform, margin=self.margin_m, z_max=self.z_max_m).point
        return self.tip(found, phi)

    def check_point(self, point: Any, phi: float = 0.0) -> np.ndarray:
        """A finite (3,) tip goal whose platform point is inside the workspace, or
        GoalRejected naming the problem (with the nearest tip that passes)."""
        goal = np.asarray(point, dtype=np.float64)
        if goal.shape != (3,):
            raise GoalRejected(f"position_m: expected 3 numbers, got shape {goal.shape}")
        if not np.isfinite(goal).all():
            raise GoalRejected(f"position_m: must be finite, got {goal.tolist()}")
        phi = self.check_phi(phi)
        if not self.inside(goal, phi):
            reason = "position_m: outside the workspace"
            if self.tool.length_m > 0.0:
                platform = ", ".join(f"{v * 1e3:.1f}" for v in self.platform(goal, phi))
                reason += f" (the platform centre would be at [{platform}] mm)"
            raise GoalRejected(reason, self.nearest(goal, phi), goal=goal, phi=phi)
        return goal

    def clamp_point(self, point: np.ndarray, phi: float = 0.0) -> np.ndarray:
        """Jog semantics: a tip whose platform point is outside the workspace moves to the
        nearest tip inside."""
        return point if self.inside(point, phi) else self.nearest(point, phi)

    def clamp_towards(
        self, start: np.ndarray, target: np.ndarray, near: np.ndarray, phi: float = 0.0
    ) -> np.ndarray:
        """Jog semantics: the point nearest ``target`` that passes every check.

        The workspace projection first; if that point breaks a joint limit or comes too
        close to a singularity, the furthest passing point on the way from ``start`` (which
        passes) towards it. Raises GoalRejected only if ``start`` itself fails.
        """
        clamped = self.clamp_point(target, phi)
        if self._passes(clamped, near, phi):
            return clamped
        if not self._passes(start, near, phi):
            raise GoalRejected("the current position fails the gate; move it back first")
        good, bad = start, clamped
        for _ in range(40):  # ~1e-12 of the jog length
            middle = 0.5 * (good + bad)
            good, bad = (middle, bad) if self._passes(middle, near, phi) else (good, middle)
        return good

    def _passes(self, point: np.ndarray, near: np.ndarray, phi: float) -> bool:
        try:
            self.solve(point, near, phi)
        except GoalRejected:
            return False
        return self.inside(point, phi)

    def solve(self, point: np.ndarray, near: np.ndarray, phi: float = 0.0) -> np.ndarray:
        """Joints (3,) [rad] for a tip (3,) [m] that passed :meth:`check_point` (IK of the
        platform point it implies); GoalRejected if unusable.

        The branch nearest the current joints first; if that breaks a limit (the arm may
        start from outside them, e.g. hanging with torque off), the working knee-out branch.
        A refusal carries ``point`` as its ``goal`` (the server offers an accepted point
        near it).
        """
        platform = self.platform(point, phi)
        joints, ok = self.robot.ik(platform, near=near)
        if not ok:
            raise GoalRejected(
                "position_m: no joint solution", self.nearest(point, phi), goal=point, phi=phi
            )
        try:
            return self.check_joints(joints)
        except GoalRejected as exc:
            knee_out = self.robot.ik(platform).joints
            if np.array_equal(knee_out, joints):
                raise GoalRejected(exc.reason, goal=point, phi=phi) from None
        try:
            return self.check_joints(knee_out)
        except GoalRejected as exc:
            raise GoalRejected(exc.reason, goal=point, phi=phi) from None

    def check_joints(self, joints: np.ndarray) -> np.ndarray:
        """Joint limits and the singularity margin; returns ``joints`` or raises."""
        for i, (value, low, high) in enumerate(
            zip(joints, self.joint_min_rad, self.joint_max_rad, strict=True)
        ):
            if not low <= value <= high:
                raise GoalRejected(
                    f"joint {i + 1}: {math.degrees(value):.1f} deg outside its limits "
                    f"[{math.degrees(low):.1f}, {math.degrees(high):.1f}] deg"
                )
        try:
            dexterity = float(self.robot.dexterity(joints))
        except DeltaError as exc:
            raise GoalRejected(f"joints: {exc}") from exc
        if not dexterity >= self.min_dexterity:
            raise GoalRejected(
                f"too close to a singularity (1/cond(J) = {dexterity:.3f} < {self.min_dexterity})"
            )
        return joints

    def check_phi(self, phi_rad: Any) -> float:
        """A wrist goal phi [rad] inside the wrist's limits, or GoalRejected naming the field.

        Without a wrist only phi = 0 passes (the tool cannot turn)."""
        try:
            phi = float(phi_rad)
        except (TypeError, ValueError):
            raise GoalRejected(f"phi_rad: expected a number, got {phi_rad!r}") from None
        if not math.isfinite(phi):
            raise GoalRejected(f"phi_rad: must be finite, got {phi}")
        low, high = self.wrist_min_rad, self.wrist_max_rad
        if low is None or high is None:
            if phi != 0.0:
                raise GoalRejected(
                    "phi_rad: no wrist axis is configured ([wrist] enabled = false), so the "
                    "tool cannot turn"
                )
            return phi
        if not low <= phi <= high:
            raise GoalRejected(
                f"phi_rad: {math.degrees(phi):.1f} deg outside the wrist's limits "
                f"[{math.degrees(low):.1f}, {math.degrees(high):.1f}] deg"
            )
        return phi

    def limit_step(self, joints: np.ndarray, previous: np.ndarray) -> np.ndarray:
        """``joints`` or, if any joint would move faster than allowed, a scaled-down step."""
        step = joints - previous
        largest = float(np.abs(step).max())
        if largest <= self.max_step_rad:
            return joints
        return previous + step * (self.max_step_rad / largest)

"""Goals in the scene: the draggable goal, saved goal points, the active path and the trail.

Dragging the gizmo sends the goal to the loop live (every drag update, not only at the
end) through ``controller.set_goal``, the same gate the REST API uses. A point outside the
workspace is projected onto it on the server (``gate.clamp_point``); when the drag ends
there the gizmo snaps back to the projected point. With a wrist the gizmo also turns about
z: its heading (the turned x axis's direction in the x-y plane, `yaw_of`) is the goal's
wrist angle phi, kept within the wrist's limits; any tilt is ignored and the gizmo snaps
back to a turn about z alone at the drag's end. Without a wrist it only translates. viser
runs these callbacks on its own threads: they only call the controller's thread-safe
methods, never the bus. Saved goal points are kept in a JSON file (app/scene/goal_store.py)
in the runs folder.
"""

from __future__ import annotations

import itertools
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import viser

from app.control.errors import GoalRejected, MotionRefused
from app.control.state import Snapshot
from app.scene.goal_store import load_points, save_points

if TYPE_CHECKING:
    from app.scene.access import SceneAccess

log = logging.getLogger(__name__)

INSIDE_COLOUR = (40, 180, 90)
PROJECTED_COLOUR = (240, 140, 30)
PATH_COLOUR = (150, 80, 200)
TRAIL_COLOUR = (30, 30, 36)
SAVED_COLOUR = (230, 190, 40)
FOLLOW_AFTER_DRAG_S = 0.5  # keep the gizmo where the operator left it this long


def yaw_of(wxyz) -> float:
    """The heading [rad] of the orientation ``wxyz`` (a unit quaternion, w first): the angle
    about z of its x axis projected on the x-y plane, atan2(R[1, 0], R[0, 0]) with
    R[0, 0] = 1 - 2 (y^2 + z^2), R[1, 0] = 2 (x y + w z) (the rotation matrix of a
    quaternion); in (-pi, pi]. A tilt about x or y does not change it."""
    w, x, y, z = (float(v) for v in wxyz)
    return math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


def about_z(phi_rad: float) -> tuple[float, float, float, float]:
    """The unit quaternion (w, x, y, z) of a turn by ``phi_rad`` [rad] about z."""
    return (math.cos(phi_rad / 2.0), 0.0, 0.0, math.sin(phi_rad / 2.0))


def polyline(points: np.ndarray) -> np.ndarray:
    """Consecutive points (N, 3) as segments (N - 1, 2, 3) for viser's line segments."""
    points = np.asarray(points, dtype=np.float64)
    return np.stack([points[:-1], points[1:]], axis=1)


class GoalView:
    """Owns the goal gizmo, goal marker, saved points, path and trail handles."""

    def __init__(
        self,
        server: viser.ViserServer,
        controller,
        trail_s: float = 4.0,
        store: Path | None = None,
        access: SceneAccess | None = None,
    ) -> None:
        self.server = server
        self.access = access  # who may drag the goal (token, lease); None: anyone
        self.store = store  # where saved points are kept across restarts (None: not kept)
        self.controller = controller
        # with a wrist the gizmo turns about z (phi, within these limits [rad]); else None
        wrist = controller.settings.wrist
        self.phi_limits = (wrist.min_angle_rad, wrist.max_angle_rad) if wrist.enabled else None
        self.trail_s = trail_s
        self.message = ""  # the last refusal, shown in the panel
        self.saved: dict[str, np.ndarray] = {}
        self._lock = threading.Lock()
        self._sequence_lock = threading.Lock()
        self._sequence = itertools.count(1)
        self._latest = 0
        self._dragging = False
        self._drag_ended_at = 0.0
        self._trail: deque[tuple[float, np.ndarray]] = deque()
        self._show_trail = True
        scene = server.scene
        snap = controller.snapshot()
        start = self._start_point(snap)
        self.phi_rad = self._goal_phi(snap) if self.phi_limits is not None else 0.0
        self.gizmo = scene.add_transform_controls(
            "/goal/gizmo",
            scale=0.07,
            disable_rotations=self.phi_limits is None,
            position=start,
            wxyz=about_z(self.phi_rad),
            depth_test=False,
        )
        self.marker = scene.add_icosphere(
            "/goal/marker", radius=0.007, color=INSIDE_COLOUR, position=start
        )
        self.path = scene.add_line_segments(
            "/goal/path", np.zeros((1, 2, 3)), PATH_COLOUR, thickness=0.003, visible=False
        )
        self.trail = scene.add_line_segments(
            "/goal/trail", np.zeros((1, 2, 3)), TRAIL_COLOUR, thickness=0.0025, visible=False
        )
        self._saved_handles: list = []
        self.gizmo.on_update(self._on_gizmo)
        if store is not None:
            self.saved = load_points(store)
            self._draw_saved()

    @property
    def gate(self):
        """The controller's gate in use (a calibration's apply replaces it): read, never
        kept, so a drag is clamped by the robot model the loop uses."""
        return self.controller.gate

    def _start_point(self, snap: Snapshot) -> np.ndarray:
        for point in (snap.goal_m, snap.point_commanded_m, snap.point_measured_m):
            if np.isfinite(point).all():
                return np.asarray(point, dtype=np.float64)
        return self.gate.nearest(np.array([0.0, 0.0, -0.24]))

    @staticmethod
    def _goal_phi(snap: Snapshot) -> float:
        """The wrist's goal [rad] (else as commanded, else as measured; 0 if none known)."""
        for phi in (snap.phi_goal_rad, snap.phi_commanded_rad, snap.phi_rad):
            if math.isfinite(phi):
                return float(phi)
        return 0.0

    # ---- dragging (viser's threads) ----
    def _on_gizmo(self, event: viser.TransformControlsEvent) -> None:
        if self.access is not None and not self.access.allow(event.client_id):
            if event.phase == "end":  # a refused drag: the gizmo goes back to the goal
                self.gizmo.position = self.marker.position
                self.gizmo.wxyz = about_z(self.phi_rad)
            return
        self._dragging = event.phase != "end"
        self.drag_pose(event.target.position, event.target.wxyz, event.phase == "end")

    def phi_of(self, wxyz) -> float | None:
        """The wrist angle [rad] a gizmo orientation ``wxyz`` asks for: its heading
        (`yaw_of`) clamped to the wrist's limits; None without a wrist (only translation)."""
        if self.phi_limits is None:
            return None
        low, high = self.phi_limits
        return min(max(yaw_of(wxyz), low), high)

    def drag_pose(self, position, wxyz, final: bool = False) -> np.ndarray | None:
        """A gizmo pose: ``position`` (3,) [m] is the tip's goal, with a wrist the turn
        ``wxyz`` (w, x, y, z) about z its phi (`phi_of`); see `drag_to`."""
        phi = self.phi_of(wxyz)
        return self.drag_to(np.asarray(position, dtype=np.float64), final, phi)

    def drag_to(
        self, point: np.ndarray, final: bool = False, phi_rad: float | None = None
    ) -> np.ndarray | None:
        """The drag path: project ``point`` [m] onto the workspace, send it as the goal,
        with a wrist at ``phi_rad`` [rad] (None: the wrist keeps its goal).

        Only the newest of overlapping drag updates is processed (viser may run them in
        parallel threads); ``final`` (drag end) snaps the gizmo to the point sent (and to a
        turn about z alone). Returns the goal handed to the loop, or None if this update
        was superseded or refused.
        """
        with self._sequence_lock:  # number and record together, or a late thread could
            sequence = next(self._sequence)  # overwrite a newer number with its older one
            self._latest = sequence
        with self._lock:
            if sequence != self._latest and not final:
                return None
            if self.phi_limits is not None and phi_rad is not None:
                self.phi_rad = float(phi_rad)
            goal = self._send(point)
            if final:
                self._drag_ended_at = time.monotonic()  # the clock Scene.update uses
                self._dragging = False
            if goal is None:
                return None
            inside = bool(np.allclose(goal, point, atol=1e-9))
            self.marker.position = goal
            self.marker.color = INSIDE_COLOUR if inside else PROJECTED_COLOUR
            if final:  # snap back onto the workspace; other clients see where it went
                self.gizmo.position = goal
                if self.phi_limits is not None:
                    self.gizmo.wxyz = about_z(self.phi_rad)
            return goal

    def _send(self, point: np.ndarray) -> np.ndarray | None:
        """gate-clamped goal handed to ``controller.set_goal``; None if refused."""
        phi = self.phi_rad if self.phi_limits is not None else 0.0
        goal = self.gate.clamp_point(point, phi)
        try:
            future = self.controller.set_goal(goal, phi)
        except GoalRejected:
            # In the workspace but past a joint limit or near a singularity: the furthest
            # good point on the way there from where the loop is now, as jog does.
            start = self._here()
            try:
                goal = self.gate.clamp_towards(start, goal, self._near(), phi)
                future = self.controller.set_goal(goal, phi)
            except (GoalRejected, MotionRefused) as exc:
                self.message = str(exc)
                return None
        except MotionRefused as exc:  # a procedure holds the robot (app/control/owner.py)
            self.message = str(exc)
            return None
        future.add_done_callback(self._outcome)
        return goal

    def _here(self) -> np.ndarray:
        return self._start_point(self.controller.snapshot())

    def _near(self) -> np.ndarray:
        near = self.controller.snapshot().joints_measured_rad
        return near if np.isfinite(near).all() else np.zeros(3)

    def _outcome(self, future: Future) -> None:
        error = future.exception()
        self.message = "" if error is None else str(error)

    # ---- saved points (GUI callbacks) ----
    def save(self, name: str, point: np.ndarray) -> str:
        """Save ``point`` [m] under ``name`` (made unique); returns the name used."""
        base = name.strip() or "point"
        unique = base
        for n in itertools.count(2):
            if unique not in self.saved:
                break
            unique = f"{base} {n}"
        self.saved[unique] = np.asarray(point, dtype=np.float64).copy()
        self._draw_saved()
        self._keep()
        return unique

    def delete(self, name: str) -> None:
        self.saved.pop(name, None)
        self._draw_saved()
        self._keep()

    def _keep(self) -> None:
        if self.store is None:
            return
        try:
            save_points(self.store, self.saved)
        except OSError as exc:  # the points stay in memory; the panel says why they won't last
            log.warning("goal points: cannot write %s: %s", self.store, exc)
            self.message = f"goal points not saved to {self.store}: {exc.strerror or exc}"

    def go_to(self, name: str, on_done: Callable[[Future], None] | None = None) -> Future:
        """Smooth move to a saved point (controller.move); GoalRejected if it is out of reach."""
        phi = self.phi_rad if self.phi_limits is not None else 0.0  # a saved point keeps phi
        future = self.controller.move(point=self.saved[name], phi_rad=phi)
        future.add_done_callback(on_done or self._outcome)
        return future

    def _draw_saved(self) -> None:
        for handle in self._saved_handles:
            handle.remove()
        scene = self.server.scene
        self._saved_handles = []
        for i, (name, point) in enumerate(self.saved.items()):
            self._saved_handles.append(
                scene.add_icosphere(
                    f"/goal/saved/{i}", radius=0.005, color=SAVED_COLOUR, position=point
                )
            )
            self._saved_handles.append(
                scene.add_label(f"/goal/saved_labels/{i}", name, position=point + [0.0, 0.0, 0.012])
            )

    # ---- display rate (the scene thread) ----
    def show_path(self, points: np.ndarray | None) -> None:
        """Draw a trajectory (N, 3) [m] as a line, or hide it with None."""
        if points is None or len(points) < 2:
            self.path.visible = False
            return
        self.path.points = polyline(points)
        self.path.visible = True

    def update(self, snap: Snapshot, now_s: float) -> None:
        """Trail of measured points; the gizmo follows goals set elsewhere (API, jog)."""
        self._update_trail(snap.point_measured_m, now_s)
        goal = snap.goal_m
        idle = not self._dragging and now_s - self._drag_ended_at > FOLLOW_AFTER_DRAG_S
        # the marker is the loop's setpoint: none (torque off) shows none, not an old goal
        has_goal = bool(np.isfinite(goal).all())
        if self.marker.visible != has_goal:
            self.marker.visible = has_goal
        if idle and np.isfinite(goal).all() and np.abs(goal - self.marker.position).max() > 1e-4:
            self.gizmo.position = goal
            self.marker.position = goal
            self.marker.color = INSIDE_COLOUR
        if idle and self.phi_limits is not None:  # and turns with wrist goals set elsewhere
            phi = self._goal_phi(snap)
            if abs(phi - self.phi_rad) > 1e-4:
                self.phi_rad = phi
                self.gizmo.wxyz = about_z(phi)

    def _update_trail(self, point: np.ndarray, now_s: float) -> None:
        changed = False
        if np.isfinite(point).all() and (
            not self._trail or np.abs(point - self._trail[-1][1]).max() > 2e-4
        ):
            self._trail.append((now_s, np.array(point)))
            changed = True
        while len(self._trail) > 1 and now_s - self._trail[0][0] > self.trail_s:
            self._trail.popleft()
            changed = True
        if changed:
            points = np.array([p for _, p in self._trail])
            if len(points) >= 2:
                self.trail.points = polyline(points)
            self.trail.visible = len(points) >= 2 and self.show_trail

    @property
    def show_trail(self) -> bool:
        return self._show_trail

    @show_trail.setter
    def show_trail(self, value: bool) -> None:
        self._show_trail = value
        self.trail.visible = value and len(self._trail) >= 2

    def remove(self) -> None:
        for handle in (self.gizmo, self.marker, self.path, self.trail, *self._saved_handles):
            handle.remove()

"""Goals in the scene: the draggable goal, saved goal points, the active path and the trail.

Dragging the gizmo sends the goal to the loop live (every drag update, not only at the
end) through ``controller.set_goal``, the same gate the REST API uses. A point outside the
workspace is projected onto it on the server (``gate.clamp_point``); when the drag ends
there the gizmo snaps back to the projected point. viser runs these callbacks on its own
threads: they only call the controller's thread-safe methods, never the bus. Saved goal
points are kept in a JSON file (app/scene/goal_store.py) in the runs folder.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import viser

from app.control.errors import GoalRejected
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
        self.gate = controller.gate
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
        start = self._start_point(controller.snapshot())
        self.gizmo = scene.add_transform_controls(
            "/goal/gizmo", scale=0.07, disable_rotations=True, position=start, depth_test=False
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

    def _start_point(self, snap: Snapshot) -> np.ndarray:
        for point in (snap.goal_m, snap.point_commanded_m, snap.point_measured_m):
            if np.isfinite(point).all():
                return np.asarray(point, dtype=np.float64)
        return self.gate.nearest(np.array([0.0, 0.0, -0.24]))

    # ---- dragging (viser's threads) ----
    def _on_gizmo(self, event: viser.TransformControlsEvent) -> None:
        if self.access is not None and not self.access.allow(event.client_id):
            if event.phase == "end":  # a refused drag: the gizmo goes back to the goal
                self.gizmo.position = self.marker.position
            return
        self._dragging = event.phase != "end"
        self.drag_to(np.asarray(event.target.position, dtype=np.float64), event.phase == "end")

    def drag_to(self, point: np.ndarray, final: bool = False) -> np.ndarray | None:
        """The drag path: project ``point`` [m] onto the workspace, send it as the goal.

        Only the newest of overlapping drag updates is processed (viser may run them in
        parallel threads); ``final`` (drag end) snaps the gizmo to the point sent. Returns
        the goal handed to the loop, or None if this update was superseded or refused.
        """
        with self._sequence_lock:  # number and record together, or a late thread could
            sequence = next(self._sequence)  # overwrite a newer number with its older one
            self._latest = sequence
        with self._lock:
            if sequence != self._latest and not final:
                return None
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
            return goal

    def _send(self, point: np.ndarray) -> np.ndarray | None:
        """gate-clamped goal handed to ``controller.set_goal``; None if refused."""
        goal = self.gate.clamp_point(point)
        try:
            future = self.controller.set_goal(goal)
        except GoalRejected:
            # In the workspace but past a joint limit or near a singularity: the furthest
            # good point on the way there from where the loop is now, as jog does.
            start = self._here()
            try:
                goal = self.gate.clamp_towards(start, goal, self._near())
                future = self.controller.set_goal(goal)
            except GoalRejected as exc:
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
        future = self.controller.move(point=self.saved[name])
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

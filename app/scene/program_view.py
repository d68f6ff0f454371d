"""The checked G-code program in the scene: its planned path, and its violations in red.

``POST /api/programs/check`` hands each report here (``Scene.show_program``), so the path
is drawn before anything moves (issue 18: "the checked path drawn before it runs,
violations in red at their points"). The path is the report's ``path_m`` (already
decimated for drawing, base frame [m]) as one polyline; each violation's first offending
sample (``point_m``) is a red point. A program that cannot be read draws nothing. This
view owns its handles; it is written from the request's thread (under a lock) and never
read by the display thread: viser sends the handles to every client, newcomers included.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import viser

from app.scene.goal_view import polyline

PATH_COLOUR = (11, 114, 133)
VIOLATION_COLOUR = (220, 30, 30)
PATH_THICKNESS_M = 0.002
VIOLATION_SIZE_M = 0.008


def _points(values: Any) -> np.ndarray:
    """``values`` as finite (N, 3) points [m]; rows with a NaN or inf are dropped."""
    array = np.asarray(values, dtype=np.float64).reshape(-1, 3)
    return array[np.isfinite(array).all(axis=1)]


class ProgramView:
    """The last checked program's path and violation points under ``root``."""

    def __init__(self, server: viser.ViserServer, root: str = "/program") -> None:
        self.server = server
        self.root = root
        self.path: viser.LineSegmentsHandle | None = None
        self.violations: viser.PointCloudHandle | None = None
        self._visible = True
        self._lock = threading.Lock()

    def show(self, path_m: Any, violation_points_m: Any) -> None:
        """Draw ``path_m`` (N, 3) [m] as a line and ``violation_points_m`` (M, 3) [m] as red
        points, replacing what was drawn; fewer than 2 path points draw no line."""
        path = _points(path_m)
        points = _points(violation_points_m)
        with self._lock:
            self._remove()
            scene = self.server.scene
            if len(path) >= 2:
                self.path = scene.add_line_segments(
                    f"{self.root}/path",
                    polyline(path),
                    PATH_COLOUR,
                    thickness=PATH_THICKNESS_M,
                    visible=self._visible,
                )
            if len(points):
                self.violations = scene.add_point_cloud(
                    f"{self.root}/violations",
                    points.astype(np.float32),
                    VIOLATION_COLOUR,
                    point_size=VIOLATION_SIZE_M,
                    point_shape="circle",
                    precision="float32",
                    visible=self._visible,
                )

    def show_report(self, report: Mapping[str, Any] | None) -> None:
        """Draw a check's report (the API's dict: ``path_m``, ``violations[].point_m``), or
        clear the drawing with None."""
        if report is None:
            self.clear()
            return
        violations: Sequence[Mapping[str, Any]] = report.get("violations") or []
        self.show(report.get("path_m") or [], [v["point_m"] for v in violations])

    def clear(self) -> None:
        """Draw no program."""
        with self._lock:
            self._remove()

    @property
    def visible(self) -> bool:
        return self._visible

    @visible.setter
    def visible(self, value: bool) -> None:
        with self._lock:
            self._visible = value
            for handle in (self.path, self.violations):
                if handle is not None:
                    handle.visible = value

    def _remove(self) -> None:
        for handle in (self.path, self.violations):
            if handle is not None:
                handle.remove()
        self.path = self.violations = None

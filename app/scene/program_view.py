"""The checked G-code program in the scene: its planned path, and its violations in red.

``POST /api/programs/check`` hands each report here (``Scene.show_program``), so the path
is drawn before anything moves (issue 18: "the checked path drawn before it runs,
violations in red at their points"). The path is the report's ``path_m`` (already
decimated for drawing, base frame [m]) as one polyline; each violation's first offending
sample (``point_m``) is a red point; while a program runs, the part of the path of the
line in execution (``path_lines``, the run's ``program_line``) is drawn over it, thicker
and orange (``show_line``). A program that cannot be read draws nothing. This
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
RUNNING_COLOUR = (245, 130, 20)
RUNNING_THICKNESS_M = 0.005


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
        self.running: viser.LineSegmentsHandle | None = None
        self.running_line: int | None = None
        self._path = np.zeros((0, 3))
        self._lines = np.zeros(0)
        self._visible = True
        self._lock = threading.Lock()

    def show(self, path_m: Any, violation_points_m: Any, path_lines: Any = None) -> None:
        """Draw ``path_m`` (N, 3) [m] as a line and ``violation_points_m`` (M, 3) [m] as red
        points, replacing what was drawn; fewer than 2 path points draw no line.
        ``path_lines`` (N,): the program line of each path point (None: unknown), for
        :meth:`show_line`."""
        raw = np.asarray(path_m, dtype=np.float64).reshape(-1, 3)
        finite = np.isfinite(raw).all(axis=1)
        path = raw[finite]
        lines = np.full(len(raw), np.nan)
        if path_lines is not None and len(path_lines) == len(raw):
            lines = np.array([np.nan if v is None else v for v in path_lines], dtype=float)
        points = _points(violation_points_m)
        with self._lock:
            self._remove()
            self._path, self._lines = path, lines[finite]
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
        points = [v["point_m"] for v in violations]
        self.show(report.get("path_m") or [], points, report.get("path_lines"))

    def show_line(self, line: int | None) -> None:
        """Draw the path of program line ``line`` over the path (the line a run executes
        now), with the points on either side so a short line still shows; None draws none."""
        with self._lock:
            if line == self.running_line:
                return
            self.running_line = line
            if self.running is not None:
                self.running.remove()
                self.running = None
            on_line = np.flatnonzero(self._lines == line) if line is not None else []
            if len(on_line) == 0:
                return
            first, last = max(on_line[0] - 1, 0), min(on_line[-1] + 1, len(self._path) - 1)
            part = self._path[first : last + 1]
            if len(part) < 2:
                return
            self.running = self.server.scene.add_line_segments(
                f"{self.root}/running",
                polyline(part),
                RUNNING_COLOUR,
                thickness=RUNNING_THICKNESS_M,
                visible=self._visible,
            )

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
            for handle in (self.path, self.violations, self.running):
                if handle is not None:
                    handle.visible = value

    def _remove(self) -> None:
        for handle in (self.path, self.violations, self.running):
            if handle is not None:
                handle.remove()
        self.path = self.violations = self.running = None
        self.running_line = None
        self._path, self._lines = np.zeros((0, 3)), np.zeros(0)

"""The scene's control panel: status, e-stop, torque, jog, goal points, view toggles.

Every callback runs on one of viser's threads and only calls the controller's thread-safe
methods (they queue work for the control thread); none touches the bus. Every control but
the e-stop first asks the clicking client's access (app/scene/access.py: the token, the
control lease); the e-stop is open to anyone. The UI shows mm;
everything handed to the controller is SI (m, s). The e-stop sits above every folder so it
is always visible.

Every field that parameterizes motion (the jog step and speed, the goal point picked for
"Go to", a point's name) belongs to the client that types it: each browser gets its own
"Jog" and "Goal points" folders (viser's per-client GUI), so a client that never unlocked
cannot change what the operator's next click does. The values are checked here, on the
server, against the API's bounds (the jog speed limit, a step of at most MAX_JOG_STEP_MM)
whoever sends them: viser itself stores any number a client sends.
"""

from __future__ import annotations

import math
import threading
from concurrent.futures import Future
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from app.control.errors import GoalRejected, MotionRefused
from app.control.state import Snapshot

if TYPE_CHECKING:
    from app.scene.access import SceneAccess
    from app.scene.goal_view import GoalView

JOG_AXES = {
    "+X": (1, 0, 0),
    "-X": (-1, 0, 0),
    "+Y": (0, 1, 0),
    "-Y": (0, -1, 0),
    "+Z": (0, 0, 1),
    "-Z": (0, 0, -1),
}
MODE_COLOURS = {"estop": "red", "fault": "red", "idle": "gray"}
MAX_JOG_STEP_MM = 50.0  # the largest step one click may ask for [mm]
DEFAULT_JOG_SPEED_MM_S = 50.0


def _open(action):
    """No access check (a panel built without ``SceneAccess``, driven from Python)."""
    return action


def _mm(point: np.ndarray) -> str:
    if not np.isfinite(point).all():
        return "—"
    return ", ".join(f"{1e3 * v:+.1f}" for v in point)


def status_markdown(snap: Snapshot, backend: str, message: str) -> str:
    """The panel's status block for one snapshot (markdown)."""
    mode = snap.mode.upper()
    torque = "torque **on**" if snap.torque else "torque off"
    lines = [
        f"**{mode}** · {torque} · {backend}",
        f"measured [mm] {_mm(snap.point_measured_m)}",
        f"goal [mm] {_mm(snap.goal_m)}",
    ]
    for fault in snap.faults[:3]:
        servo = f" (servo {fault.servo_id})" if fault.servo_id is not None else ""
        times = f" (×{fault.count})" if fault.count > 1 else ""
        lines.append(f"⚠ **{fault.source}**{servo}: {fault.reason}{times}")
    if snap.warning:
        lines.append(f"⚠ {snap.warning}")
    if message:
        lines.append(f"_{message}_")
    return "  \n".join(lines)


def check_jog(step_mm: float, speed_mm_s: float, speed_limit_mm_s: float) -> str | None:
    """Why a scene jog of ``step_mm`` [mm] at ``speed_mm_s`` [mm/s] is refused, or None.

    The API's bounds, on the server: 0 < step <= MAX_JOG_STEP_MM, 0 < speed <= the jog speed
    limit (``[jog] max_velocity_m_s``), both finite.
    """
    step, speed = float(step_mm), float(speed_mm_s)
    if not (math.isfinite(step) and 0.0 < step <= MAX_JOG_STEP_MM):
        return (
            f"jog step {step:g} mm refused: it must be more than 0 and at most "
            f"{MAX_JOG_STEP_MM:g} mm"
        )
    if not (math.isfinite(speed) and 0.0 < speed <= speed_limit_mm_s):
        return (
            f"jog speed {speed:g} mm/s refused: it must be more than 0 and at most the jog "
            f"speed limit {speed_limit_mm_s:g} mm/s"
        )
    return None


class ControlPanel:
    """GUI handles (``gui_*``) for operating the robot from the scene.

    The shared handles (status, e-stop, reset, torque) carry no value that parameterizes
    motion; each client's own Jog and Goal points folders are built when it connects
    (``handle(client_id, name)`` finds them).
    """

    def __init__(
        self,
        server: viser.ViserServer,
        controller,
        goals: GoalView,
        access: SceneAccess | None = None,
    ) -> None:
        self.controller = controller
        self.goals = goals
        self.message = ""
        # every control but the e-stop asks the client's access (token, lease) first
        self._guard = guard = access.guarded if access is not None else _open
        jog = getattr(getattr(controller, "settings", None), "jog", None)
        self.jog_speed_limit_mm_s = 1e3 * getattr(jog, "max_velocity_m_s", 0.5)
        self.default_step_mm = min(1e3 * getattr(jog, "step_m", 0.005), MAX_JOG_STEP_MM)
        self.default_speed_mm_s = min(DEFAULT_JOG_SPEED_MM_S, self.jog_speed_limit_mm_s)
        self._clients: dict[int, dict[str, Any]] = {}
        self._lock = threading.Lock()
        gui = server.gui
        self.gui_status = gui.add_markdown("connecting…")
        self.gui_estop = gui.add_button("E-STOP", color="red", icon=viser.Icon.HAND_STOP)
        self.gui_reset = gui.add_button("Reset e-stop / faults", icon=viser.Icon.REFRESH)
        self.gui_torque = gui.add_button_group("Torque", ("on", "off"))
        self.gui_estop.on_click(lambda _: self._call(self.controller.estop))
        self.gui_reset.on_click(guard(lambda _: self._call(self.controller.reset)))
        self.gui_torque.on_click(
            guard(lambda e: self._call(self.controller.set_torque, e.target.value == "on"))
        )
        # the per-client folders sit right below the torque buttons
        self._order = float(self.gui_torque.order)
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(lambda client: self._forget(client.client_id))

    # ---- each client's own folders (viser's threads) ----
    def _on_connect(self, client: viser.ClientHandle) -> None:
        gui, guard = client.gui, self._guard
        handles: dict[str, Any] = {}
        with gui.add_folder("Jog", order=self._order + 0.25):
            step = gui.add_number(
                "Step [mm]", self.default_step_mm, min=0.1, max=MAX_JOG_STEP_MM, step=0.5
            )
            speed = gui.add_number(
                "Speed [mm/s]",
                self.default_speed_mm_s,
                min=1.0,
                max=self.jog_speed_limit_mm_s,
                step=5.0,
            )
            jog = gui.add_button_group("Jog", tuple(JOG_AXES))
        jog.on_click(guard(lambda e: self.jog(JOG_AXES[e.target.value], step.value, speed.value)))
        with gui.add_folder("Goal points", order=self._order + 0.5, expand_by_default=False):
            name = gui.add_text("Name", self.next_point_name())
            save = gui.add_button("Save current goal", icon=viser.Icon.PIN)
            points = gui.add_dropdown("Saved", self._point_options())
            go_to = gui.add_button("Go to", icon=viser.Icon.PLAYER_PLAY)
            delete = gui.add_button("Delete", icon=viser.Icon.TRASH)
        # saving and deleting change where a later "Go to" goes: they need control too
        save.on_click(guard(lambda _: self._save_from(handles)))
        go_to.on_click(guard(lambda _: self.go_to(points.value)))
        delete.on_click(guard(lambda _: self.delete_point(points.value)))
        handles.update(
            jog_step=step,
            jog_speed=speed,
            jog=jog,
            point_name=name,
            save_point=save,
            points=points,
            go_to=go_to,
            delete_point=delete,
        )
        with self._lock:
            self._clients[client.client_id] = handles

    def _forget(self, client_id: int) -> None:
        with self._lock:
            self._clients.pop(client_id, None)

    def handle(self, client_id: int, name: str) -> Any:
        """One of this client's own GUI handles: "jog_step", "jog_speed", "jog",
        "point_name", "save_point", "points", "go_to", "delete_point" (None before its
        folders are built)."""
        with self._lock:
            return self._clients.get(client_id, {}).get(name)

    def _each_client(self) -> list[dict[str, Any]]:
        with self._lock:
            return list(self._clients.values())

    # ---- callbacks (viser's threads) ----
    def _call(self, method, *args) -> None:
        """Run a controller command; a refusal becomes the panel's message, not an error."""
        try:
            future: Future = method(*args)
        except (GoalRejected, MotionRefused, RuntimeError) as exc:
            self.message = str(exc)
            return
        future.add_done_callback(self._outcome)

    def _outcome(self, future: Future) -> None:
        error = future.exception()
        self.message = "" if error is None else str(error)

    def jog(
        self,
        direction: tuple[int, int, int],
        step_mm: float | None = None,
        speed_mm_s: float | None = None,
    ) -> None:
        """One bounded jog step of ``step_mm`` [mm] along ``direction`` at ``speed_mm_s``
        [mm/s] (None: the panel's defaults); refused, with the reason as the panel's
        message and nothing moved, outside :func:`check_jog`'s bounds.

        viser buttons are clicks, not press-and-hold, so the scene jogs in discrete steps
        (hold-to-move's safe equivalent: each click moves at most one step). The step is
        relative to what the loop commands when it runs (controller.jog), never to a goal
        this panel saw earlier: after torque off and on it moves by the step only.
        """
        step = self.default_step_mm if step_mm is None else step_mm
        speed = self.default_speed_mm_s if speed_mm_s is None else speed_mm_s
        try:
            refused = check_jog(step, speed, self.jog_speed_limit_mm_s)
        except (TypeError, ValueError):
            refused = f"jog step {step!r} mm / speed {speed!r} mm/s refused: not numbers"
        if refused is not None:
            self.message = refused
            return
        delta = 1e-3 * float(step) * np.asarray(direction, dtype=np.float64)
        self._call(self.controller.jog, delta, 1e-3 * float(speed))

    def _save_from(self, handles: dict[str, Any]) -> None:
        """One client's Save: its name field, then its dropdown picks the point saved."""
        kept = self.save_point(handles["point_name"].value)
        if kept is not None:
            handles["points"].value = kept
            handles["point_name"].value = self.next_point_name()

    def save_point(self, name: str) -> str | None:
        """Save the current goal (else the measured point) as ``name``; returns the name kept."""
        snap = self.controller.snapshot()
        point = snap.goal_m if np.isfinite(snap.goal_m).all() else snap.point_measured_m
        if not np.isfinite(point).all():
            self.message = "no goal or measured position to save yet"
            return None
        kept = self.goals.save(name, point)
        self._refresh_points()
        return kept

    def go_to(self, name: str) -> None:
        if name not in self.goals.saved:
            self.message = "save a goal point first"
            return
        self._call(self.goals.go_to, name, self._outcome)

    def delete_point(self, name: str) -> None:
        self.goals.delete(name)
        self._refresh_points()

    def next_point_name(self) -> str:
        """The name offered for the next saved point."""
        return f"point {len(self.goals.saved) + 1}"

    def point_names(self) -> tuple[str, ...]:
        """The saved points' names, as every client's dropdown lists them."""
        return tuple(self.goals.saved)

    def _point_options(self) -> tuple[str, ...]:
        return self.point_names() or ("—",)

    def _refresh_points(self) -> None:
        """Every client's dropdown lists the saved points; each keeps its own pick."""
        names = self._point_options()
        for handles in self._each_client():
            points = handles["points"]
            keep = points.value
            points.options = names
            points.value = keep if keep in names else names[0]

    # ---- display rate (scene thread) ----
    def update(self, snap: Snapshot) -> None:
        message = self.message or self.goals.message
        text = status_markdown(snap, snap.info.backend_description, message)
        if text != self.gui_status.content:
            self.gui_status.content = text

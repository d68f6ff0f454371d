"""The scene's control panel: status, e-stop, torque, jog, goal points, view toggles.

Every callback runs on one of viser's threads and only calls the controller's thread-safe
methods (they queue work for the control thread); none touches the bus. Every control but
the e-stop first asks the clicking client's access (app/scene/access.py: the token, the
control lease); the e-stop is open to anyone. The UI shows mm;
everything handed to the controller is SI (m, s). The e-stop sits above every folder so it
is always visible.
"""

from __future__ import annotations

from concurrent.futures import Future
from typing import TYPE_CHECKING

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


class ControlPanel:
    """GUI handles (``gui_*``) for operating the robot from the scene."""

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
        guard = access.guarded if access is not None else _open
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
        with gui.add_folder("Jog"):
            self.gui_jog_step = gui.add_number("Step [mm]", 5.0, min=0.1, max=50.0, step=0.5)
            self.gui_jog_speed = gui.add_number("Speed [mm/s]", 50.0, min=1.0, max=500.0, step=5.0)
            self.gui_jog = gui.add_button_group("Jog", tuple(JOG_AXES))
            self.gui_jog.on_click(guard(lambda e: self.jog(JOG_AXES[e.target.value])))
        self._add_goal_points(gui, guard)

    def _add_goal_points(self, gui, guard) -> None:
        with gui.add_folder("Goal points", expand_by_default=False):
            self.gui_point_name = gui.add_text("Name", "point 1")
            self.gui_save_point = gui.add_button("Save current goal", icon=viser.Icon.PIN)
            self.gui_points = gui.add_dropdown("Saved", ("—",))
            self.gui_go_to = gui.add_button("Go to", icon=viser.Icon.PLAYER_PLAY)
            self.gui_delete_point = gui.add_button("Delete", icon=viser.Icon.TRASH)
        self.gui_save_point.on_click(lambda _: self.save_point())
        self.gui_go_to.on_click(guard(lambda _: self.go_to(self.gui_points.value)))
        self.gui_delete_point.on_click(lambda _: self.delete_point(self.gui_points.value))
        if self.goals.saved:  # kept from an earlier session
            self._refresh_points(None)
            self.gui_point_name.value = f"point {len(self.goals.saved) + 1}"

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

    def jog(self, direction: tuple[int, int, int]) -> None:
        """One bounded jog step along ``direction`` at the panel's speed.

        viser buttons are clicks, not press-and-hold, so the scene jogs in discrete steps
        (hold-to-move's safe equivalent: each click moves at most one step). The step is
        relative to what the loop commands when it runs (controller.jog), never to a goal
        this panel saw earlier: after torque off and on it moves by the step only.
        """
        step_m = 1e-3 * float(self.gui_jog_step.value)
        speed_m_s = 1e-3 * float(self.gui_jog_speed.value)
        delta = step_m * np.asarray(direction, dtype=np.float64)
        self._call(self.controller.jog, delta, speed_m_s)

    def save_point(self) -> None:
        snap = self.controller.snapshot()
        point = snap.goal_m if np.isfinite(snap.goal_m).all() else snap.point_measured_m
        if not np.isfinite(point).all():
            self.message = "no goal or measured position to save yet"
            return
        name = self.goals.save(self.gui_point_name.value, point)
        self._refresh_points(name)
        self.gui_point_name.value = f"point {len(self.goals.saved) + 1}"

    def go_to(self, name: str) -> None:
        if name not in self.goals.saved:
            self.message = "save a goal point first"
            return
        self._call(self.goals.go_to, name, self._outcome)

    def delete_point(self, name: str) -> None:
        self.goals.delete(name)
        self._refresh_points(None)

    def _refresh_points(self, selected: str | None) -> None:
        names = tuple(self.goals.saved) or ("—",)
        self.gui_points.options = names
        self.gui_points.value = selected if selected in names else names[0]

    # ---- display rate (scene thread) ----
    def update(self, snap: Snapshot) -> None:
        message = self.message or self.goals.message
        text = status_markdown(snap, self.controller.backend_description, message)
        if text != self.gui_status.content:
            self.gui_status.content = text

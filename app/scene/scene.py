"""The 3D scene: a viser server beside the control server, drawing the robot live.

``Scene`` owns the viser server and every view and panel on it. ``start()`` builds them and
starts a display thread that, about 30 times a second, reads the controller's latest
snapshot and sends every change in one ``server.atomic()`` batch; ``stop()`` ends both. The
display thread only reads snapshots; operator actions go through viser's callbacks to the
controller's thread-safe methods. Nothing here ever touches the servo bus.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import viser

from app.control.authority import Authority, is_loopback
from app.control.model import reach_m
from app.origins import OriginPolicy
from app.scene.access import SceneAccess
from app.scene.goal_store import FILE_NAME as POINTS_FILE
from app.scene.goal_view import GoalView
from app.scene.origins import guarded_viser_server
from app.scene.panel import ControlPanel
from app.scene.program_view import ProgramView
from app.scene.robot_view import RobotView
from app.scene.run_panel import RunPanel
from app.scene.workspace_view import WorkspaceView
from app.scene.world_view import WorldView
from kinematics import Pose

log = logging.getLogger(__name__)
PANEL_EVERY = 3  # frames per panel refresh: 10 Hz is plenty for text and the plot


class Scene:
    """The operator's 3D view of one controller.

    controller: the running ``Controller``; runs: returns the ``RunManager`` (or None);
    host, port: where viser listens (port 0 picks a free one); rate_hz: display rate [Hz].
    """

    def __init__(
        self,
        controller: Any,
        runs: Callable[[], Any] = lambda: None,
        host: str = "127.0.0.1",
        port: int = 8080,
        rate_hz: float = 30.0,
        authority: Authority | None = None,
    ) -> None:
        self.controller = controller
        # the app's Authority, shared with the HTTP API; alone, the scene keeps its own
        self.authority = authority or Authority(
            None, getattr(getattr(controller.settings, "server", None), "lease_timeout_s", 30.0)
        )
        self.runs = runs
        self.host = host
        self.port = port
        self.period_s = 1.0 / rate_hz
        self.server: viser.ViserServer | None = None
        self.frames = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """Where the scene is served (the bound port once started)."""
        port = self.server.get_port() if self.server is not None else self.port
        return f"http://{self.host}:{port}/"

    def start(self) -> None:
        """Serve the scene and start the display thread (blocks ~0.5 s while meshing)."""
        # pages of other sites and DNS rebinding are refused on this port (app/origins.py)
        policy = OriginPolicy.from_settings(getattr(self.controller.settings, "server", None))
        server = guarded_viser_server(
            policy, host=self.host, port=self.port, label="deltadash", verbose=False
        )
        self.server = server
        settings, model = self.controller.settings, self.controller.model
        robot = model.robot
        self._frame_camera(server)
        server.scene.add_frame("/base_frame", axes_length=0.05, axes_radius=0.002)
        tool = model.gate.tool
        self._model_version = model.version
        self.workspace = self._workspace_view(server, model)
        lowest = float(self.workspace.mesh.vertices[:, 2].min()) + min(tool.offset_m[2], 0.0)
        floor = lowest - 0.02
        server.scene.add_grid(
            "/floor", 0.8, 0.8, cell_size=0.05, section_size=0.1, position=(0.0, 0.0, floor)
        )
        self.robot = RobotView(server, robot, "/robot", tool=tool)
        self.ghost = RobotView(server, robot, "/ghost", ghost=True, tool=tool)
        runs_settings = getattr(settings, "runs", None)
        store = runs_settings.folder_path / POINTS_FILE if runs_settings is not None else None
        self.access = SceneAccess(server, self.authority)
        self.goals = GoalView(server, self.controller, store=store, access=self.access)
        self.panel = ControlPanel(server, self.controller, self.goals, self.access)
        self.tests = RunPanel(server, self.runs, self.goals.show_path, self.access)
        self.world = WorldView(server, _mount(settings))
        self.program = ProgramView(server)
        self._add_view_toggles(server)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="deltadash-scene", daemon=True)
        self._thread.start()

    def _workspace_view(self, server: viser.ViserServer, model: Any) -> WorkspaceView:
        """The tori and reachable volume of ``model`` (the controller's robot model), with
        the gate's margin and ceiling (meshing takes ~0.5 s)."""
        gate = model.gate
        return WorkspaceView(
            server, model.robot, gate.margin_m, gate.z_max_m, tool_offset_m=gate.tool.offset_m
        )

    def _follow_model(self, server: viser.ViserServer) -> None:
        """A calibration's apply replaced the controller's robot model: draw the links and
        the workspace of the new one (the display thread; the volume is meshed again)."""
        model = self.controller.model
        if model.version == self._model_version:
            return
        self._model_version = model.version
        self.robot.use_robot(model.robot)
        self.ghost.use_robot(model.robot)
        tori, volume = self.workspace.tori_visible, self.workspace.volume_visible
        self.workspace.remove()
        self.workspace = self._workspace_view(server, model)
        self.workspace.tori_visible, self.workspace.volume_visible = tori, volume

    def _frame_camera(self, server: viser.ViserServer) -> None:
        reach = reach_m(self.controller.robot)
        server.initial_camera.position = (0.75 * reach, -0.95 * reach, 0.05 * reach)
        server.initial_camera.look_at = (-0.1 * reach, 0.1 * reach, -0.45 * reach)
        server.initial_camera.up = (0.0, 0.0, 1.0)
        server.scene.set_up_direction("+z")

    def _add_view_toggles(self, server: viser.ViserServer) -> None:
        gui = server.gui
        with gui.add_folder("View", expand_by_default=False):
            self.gui_tori = gui.add_checkbox("Leg tori (Fig. 4.2)", True)
            self.gui_volume = gui.add_checkbox("Reachable volume", True)
            self.gui_ghost = gui.add_checkbox("Commanded pose (ghost)", True)
            self.gui_trail = gui.add_checkbox("Measured trail", True)
            self.gui_program = gui.add_checkbox("Checked program", True)
        self.gui_tori.on_update(lambda e: setattr(self.workspace, "tori_visible", e.target.value))
        self.gui_volume.on_update(
            lambda e: setattr(self.workspace, "volume_visible", e.target.value)
        )
        self.gui_ghost.on_update(lambda e: setattr(self.ghost, "visible", e.target.value))
        self.gui_trail.on_update(lambda e: setattr(self.goals, "show_trail", e.target.value))
        self.gui_program.on_update(lambda e: setattr(self.program, "visible", e.target.value))

    def show_program(self, report: Mapping[str, Any] | None) -> None:
        """Draw a checked program (POST /api/programs/check's report: its path and its
        violations in red), or none; from any thread, a no-op before ``start()``."""
        program: ProgramView | None = getattr(self, "program", None)
        if program is not None:
            program.show_report(report)

    def stop(self) -> None:
        """Stop the display thread and the viser server."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self.server is not None:
            self.server.stop()
            self.server = None

    # ---- the display thread ----
    def _run(self) -> None:
        deadline = time.monotonic()
        while not self._stop.wait(max(0.0, deadline - time.monotonic())):
            deadline = max(deadline + self.period_s, time.monotonic() - self.period_s)
            server = self.server
            if server is None or not server.get_clients():
                continue  # nobody is looking: the handles keep the last state for newcomers
            try:
                self.update(time.monotonic())
            except Exception:  # a drawing bug must not end the display (or the app)
                log.exception("scene update failed")

    def _program_line(self) -> int | None:
        """The line a running G-code program executes now, None when none runs."""
        runs = self.runs()
        listed = runs.list() if runs is not None else []
        latest = listed[0] if listed else None
        if latest is None or latest.state != "running" or latest.kind != "program":
            return None
        return (runs.progress(latest.run_id) or {}).get("program_line")

    def _pose_input(self) -> Any:
        """The drone's pose input as the node last said (its status), for the drone drawn
        outside a hold; None when the controller has no node (in-process)."""
        node_status = getattr(self.controller, "node_status", None)
        return None if node_status is None else node_status().get("pose")

    def update(self, now_s: float) -> None:
        """One display frame from the controller's latest snapshot, sent as one batch."""
        snap = self.controller.snapshot()
        assert self.server is not None
        self._follow_model(self.server)
        with self.server.atomic():
            self.robot.update(snap.joints_measured_rad, snap.phi_rad)
            commanded = np.isfinite(snap.joints_commanded_rad).all()
            phi_commanded = snap.phi_commanded_rad  # NaN without a wrist
            self.ghost.update(
                snap.joints_commanded_rad,
                phi_commanded if np.isfinite(phi_commanded) else snap.phi_rad,
            )
            self.ghost.visible = bool(commanded and self.gui_ghost.value)
            self.goals.update(snap, now_s)
            self.world.update(snap, self._pose_input())
            self.tests.record(snap, now_s)
            if self.frames % PANEL_EVERY == 0:
                self.panel.update(snap)
                self.tests.update(now_s)
                self.program.show_line(self._program_line())
        self.frames += 1


def _mount(settings: Any) -> Pose:
    """The base's pose in the drone body (settings.world), identity where there is none."""
    world = getattr(settings, "world", None)
    if world is None:
        return Pose.identity()
    return Pose.from_arrays(world.mount_position_m, world.mount_quaternion)


def scene_host(host: str) -> str:
    """Where the scene may listen: viser serves the robot's view to anyone who connects
    (only its controls are locked by the token), so beyond loopback it stays on 127.0.0.1
    (reach it by SSH tunnel)."""
    loopback = is_loopback(host)
    if not loopback:
        log.warning("3D scene bound to 127.0.0.1, not %s: its view has no token check", host)
    return host if loopback else "127.0.0.1"


def start_scene(
    settings: Any, controller: Any, runs: Callable[[], Any], authority: Authority | None = None
) -> Scene | None:
    """The lifespan's hook: a started Scene per ``settings.server``, or None if disabled;
    ``authority`` is the app's (the scene's controls obey the same token and lease)."""
    if not settings.server.scene:
        return None
    host = scene_host(settings.server.host)
    scene = Scene(controller, runs, host, settings.server.viser_port, authority=authority)
    scene.start()
    wanted = settings.server.viser_port
    if scene.server is not None and wanted and scene.server.get_port() != wanted:
        print(f"deltadash: port {wanted} is taken: 3D scene on {scene.url}", flush=True)
    return scene

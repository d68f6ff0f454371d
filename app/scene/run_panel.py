"""The scene's run panel: the thesis's sinusoid (ch. 6.1), preview, start/abort, live
tracking error (uPlot) and the last run's statistics.

Runs belong to ``app.runs`` (the RunManager in ``app.state.runs``); it is imported lazily so
the scene still works, with a clear message in the panel, where test runs are missing. The
UI shows mm and deg; ``SinusoidParams`` is SI.

The sinusoid's fields (amplitude, frequency, phase, offset, duration, feed-forward) and its
buttons belong to each client (viser's per-client GUI): what one browser types never
changes what another's Start runs. The run manager checks the parameters, whoever sent
them, as it checks the API's (the plan within the workspace, joint and speed limits).
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from app.control.state import Snapshot

if TYPE_CHECKING:
    from app.scene.access import SceneAccess

PLOT_WINDOW_S = 10.0
FIELDS = ("amplitude", "frequency", "phase", "offset", "duration", "feedforward")
AXIS_COLOURS = ("#de4c40", "#40a85a", "#3c70d6")


def _load_runs_api() -> tuple[Any, Any] | str:
    """(SinusoidParams, sinusoid_points), or why they cannot be used."""
    try:
        from app.runs.trajectories import SinusoidParams, sinusoid_points
    except ImportError as exc:  # issue 6 not installed here
        return f"test runs are not available in this build ({exc})"
    return SinusoidParams, sinusoid_points


def _finite(value: Any, name: str, count: int) -> tuple[float, ...]:
    """``count`` finite floats from a field's value, or ValueError naming ``name``."""
    try:
        numbers = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected {count} numbers, got {value!r}") from None
    if len(numbers) != count or not all(math.isfinite(v) for v in numbers):
        raise ValueError(f"{name}: expected {count} finite numbers, got {value!r}")
    return numbers


def stats_markdown(run: Any) -> str:
    """Summary of one run (``app.runs.run.Run``): state and per-axis RMSE / max [mm]."""
    lines = [f"**{run.run_id}** · {run.state}" + (f" ({run.reason})" if run.reason else "")]
    tracking = (run.stats or {}).get("tracking") or {}
    for axis in ("x", "y", "z"):
        values = tracking.get(axis)
        if values:
            lines.append(
                f"{axis}: RMSE {1e3 * values['rmse_m']:.2f} mm, "
                f"max {1e3 * values['max_abs_m']:.2f} mm"
            )
    return "  \n".join(lines)


class RunPanel:
    """Sinusoid parameters, preview, start/abort, tracking-error plot, last run stats.

    runs: returns the RunManager (or None before the app has one); show_path: draws a
    path (N, 3) [m] in the scene, or hides it with None. Each client's fields and buttons
    are built when it connects (``handle(client_id, name)`` finds them); the result text
    and the plot are shared.
    """

    def __init__(
        self,
        server: viser.ViserServer,
        runs: Callable[[], Any],
        show_path: Callable[[np.ndarray | None], None],
        access: SceneAccess | None = None,
    ) -> None:
        self.runs = runs
        # start, preview and abort ask the clicking client's access (token, lease) first
        self._guard = access.guarded if access is not None else (lambda action: action)
        self.show_path = show_path
        self.message = ""
        self.run_id: str | None = None
        self._shown_run: str | None = None
        self._errors: deque[tuple[float, np.ndarray]] = deque()
        self._last_stats = ""
        self._clients: dict[int, dict[str, Any]] = {}
        self._lock = threading.Lock()
        gui = server.gui
        api = _load_runs_api()
        with gui.add_folder("Test: last run") as folder:
            if isinstance(api, str):
                self.gui_unavailable = gui.add_markdown(f"⚠ {api}")
                self.params_type = None
            else:
                self.params_type, self.sinusoid_points = api
            self.gui_result = gui.add_markdown("")
        # each client's inputs go above the shared result, inside a folder of their own
        self._order = float(folder.order) - 0.5
        with gui.add_folder("Tracking error [mm]"):
            self.gui_plot = gui.add_uplot(
                self._plot_data(),
                self._series(),
                title="commanded − measured",
                scales={"x": {"time": False, "auto": True}, "y": {"auto": True}},
                aspect=1.6,
            )
        if self.params_type is not None:
            server.on_client_connect(self._on_connect)
            server.on_client_disconnect(lambda client: self._forget(client.client_id))

    def _on_connect(self, client: viser.ClientHandle) -> None:
        gui, defaults = client.gui, self.params_type()
        mm = lambda v: tuple(1e3 * x for x in v)  # noqa: E731
        with gui.add_folder("Test: sinusoid", order=self._order):
            handles: dict[str, Any] = {
                "amplitude": gui.add_vector3("Amplitude [mm]", mm(defaults.amplitude_m), step=1.0),
                "frequency": gui.add_vector3("Frequency [Hz]", defaults.frequency_hz, step=0.1),
                "phase": gui.add_vector3(
                    "Phase [deg]", tuple(math.degrees(p) for p in defaults.phase_rad), step=5.0
                ),
                "offset": gui.add_vector3("Offset [mm]", mm(defaults.offset_m), step=1.0),
                "duration": gui.add_number(
                    "Duration [s]", defaults.duration_s, min=0.5, max=600.0, step=0.5
                ),
                "feedforward": gui.add_checkbox("Feed-forward", defaults.feedforward),
                "preview": gui.add_button("Preview path", icon=viser.Icon.ROUTE),
                "start": gui.add_button("Start", color="green", icon=viser.Icon.PLAYER_PLAY),
                "abort": gui.add_button("Abort", color="orange", icon=viser.Icon.PLAYER_STOP),
            }
        values = lambda: self._values_of(handles)  # noqa: E731
        handles["preview"].on_click(lambda _: self.preview(values()))
        handles["start"].on_click(self._guard(lambda _: self.start(values())))
        handles["abort"].on_click(self._guard(lambda _: self.abort()))
        with self._lock:
            self._clients[client.client_id] = handles

    def _forget(self, client_id: int) -> None:
        with self._lock:
            self._clients.pop(client_id, None)

    def handle(self, client_id: int, name: str) -> Any:
        """One of this client's own handles: "amplitude", "frequency", "phase", "offset",
        "duration", "feedforward", "preview", "start", "abort" (None before it is built)."""
        with self._lock:
            return self._clients.get(client_id, {}).get(name)

    @staticmethod
    def _values_of(handles: dict[str, Any]) -> dict[str, Any]:
        return {name: handle.value for name, handle in handles.items() if name in FIELDS}

    def params(self, values: dict[str, Any] | None = None) -> Any:
        """SinusoidParams (SI) from one client's field values (UI units: mm, Hz, deg, s;
        None: the defaults); ValueError naming the field when one is not finite numbers."""
        defaults = self.params_type()
        if values is None:
            return defaults
        try:
            amplitude = _finite(values["amplitude"], "amplitude_m", 3)
            frequency = _finite(values["frequency"], "frequency_hz", 3)
            phase = _finite(values["phase"], "phase_rad", 3)
            offset = _finite(values["offset"], "offset_m", 3)
            duration = _finite((values["duration"],), "duration_s", 1)[0]
        except KeyError as exc:
            raise ValueError(f"{exc.args[0]}: missing") from None
        return self.params_type(
            amplitude_m=tuple(1e-3 * v for v in amplitude),
            frequency_hz=frequency,
            phase_rad=tuple(math.radians(v) for v in phase),
            offset_m=tuple(1e-3 * v for v in offset),
            duration_s=duration,
            feedforward=bool(values.get("feedforward", defaults.feedforward)),
        )

    def path_of(self, params: Any) -> np.ndarray:
        """The timed part of the sinusoid, (N, 3) [m], about 100 points per second."""
        count = int(min(max(100 * params.duration_s, 50), 3000))
        return self.sinusoid_points(params, np.linspace(0.0, params.duration_s, count))

    # ---- callbacks (viser's threads) ----
    def preview(self, values: dict[str, Any] | None = None) -> None:
        if self.params_type is None:
            return
        try:
            params = self.params(values)
            if not 0.0 < params.duration_s <= 600.0:
                raise ValueError(f"duration_s: {params.duration_s:g} s is not in (0, 600]")
        except ValueError as exc:
            self.message = f"no preview: {exc}"
            return
        self.show_path(self.path_of(params))
        self.message = "preview: the path drawn in purple"

    def start(self, values: dict[str, Any] | None = None) -> None:
        runs = self.runs() if self.params_type is not None else None
        if runs is None:
            self.message = "test runs are not available"
            return
        try:
            params = self.params(values)
            run = runs.start_sinusoid(params)
        except Exception as exc:  # GoalRejected, MotionRefused, timeouts: say why, stay up
            self.message = f"not started: {exc}"
            return
        self.run_id = run.run_id
        self.message = f"running {run.run_id}"

    def abort(self) -> None:
        runs = self.runs()
        if runs is None or self.run_id is None:
            self.message = "no run started from this panel"
            return
        try:
            runs.abort(self.run_id)
        except Exception as exc:  # e.g. the loop did not answer in time
            self.message = f"abort: {exc}"

    # ---- display rate (scene thread) ----
    def record(self, snap: Snapshot, now_s: float) -> None:
        """Keep the last PLOT_WINDOW_S of tracking error (commanded - measured) [m]."""
        error = snap.tracking_error_m
        if np.isfinite(error).all():
            self._errors.append((now_s, error))
        while self._errors and now_s - self._errors[0][0] > PLOT_WINDOW_S:
            self._errors.popleft()

    def update(self, now_s: float) -> None:
        """Refresh the plot and the result text (call a few times a second)."""
        self.gui_plot.data = self._plot_data(now_s)
        text = self._result_text()
        if text != self._last_stats:
            self._last_stats = text
            self.gui_result.content = text

    def _result_text(self) -> str:
        runs = self.runs()
        latest = runs.list()[0] if runs is not None and runs.list() else None
        self._follow(latest)
        parts = [f"_{self.message}_"] if self.message else []
        if latest is not None:
            parts.append("**Last run**  \n" + stats_markdown(latest))
        return "  \n".join(parts)

    def _follow(self, latest: Any) -> None:
        """Draw the active run's path (started here or through the API); clear it after."""
        running = latest is not None and latest.state == "running"
        if running and self._shown_run != latest.run_id and self.params_type is not None:
            try:
                self.show_path(self.path_of(self.params_type(**latest.params)))
            except (TypeError, ValueError):  # a run kind without sinusoid parameters
                self.show_path(None)
            self._shown_run = latest.run_id
        elif not running and self._shown_run is not None:
            self.show_path(None)
            self._shown_run = None
            if self.message.startswith("running"):
                self.message = ""

    def _plot_data(self, now_s: float | None = None) -> tuple[np.ndarray, ...]:
        if not self._errors or now_s is None:
            return (np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2))
        times = np.array([t for t, _ in self._errors]) - now_s
        errors = 1e3 * np.array([e for _, e in self._errors])
        return (times, errors[:, 0], errors[:, 1], errors[:, 2])

    @staticmethod
    def _series() -> tuple[dict, ...]:
        axis = [
            {"label": name, "stroke": colour, "width": 1.5}
            for name, colour in zip("xyz", AXIS_COLOURS, strict=True)
        ]
        return ({"label": "t [s]"}, *axis)

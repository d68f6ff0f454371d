"""The scene's run panel: the thesis's sinusoid (ch. 6.1), preview, start/abort, live
tracking error (uPlot) and the last run's statistics.

Runs belong to ``app.runs`` (the RunManager in ``app.state.runs``); it is imported lazily so
the scene still works, with a clear message in the panel, where test runs are missing. The
UI shows mm and deg; ``SinusoidParams`` is SI.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from app.control.state import Snapshot

if TYPE_CHECKING:
    from app.scene.access import SceneAccess

PLOT_WINDOW_S = 10.0
AXIS_COLOURS = ("#de4c40", "#40a85a", "#3c70d6")


def _load_runs_api() -> tuple[Any, Any] | str:
    """(SinusoidParams, sinusoid_points), or why they cannot be used."""
    try:
        from app.runs.trajectories import SinusoidParams, sinusoid_points
    except ImportError as exc:  # issue 6 not installed here
        return f"test runs are not available in this build ({exc})"
    return SinusoidParams, sinusoid_points


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
    path (N, 3) [m] in the scene, or hides it with None.
    """

    def __init__(
        self,
        server: viser.ViserServer,
        runs: Callable[[], Any],
        show_path: Callable[[np.ndarray | None], None],
        access: SceneAccess | None = None,
    ) -> None:
        self.runs = runs
        # start and abort ask the clicking client's access (token, lease) first
        self._guard = access.guarded if access is not None else (lambda action: action)
        self.show_path = show_path
        self.message = ""
        self.run_id: str | None = None
        self._shown_run: str | None = None
        self._errors: deque[tuple[float, np.ndarray]] = deque()
        self._last_stats = ""
        gui = server.gui
        api = _load_runs_api()
        with gui.add_folder("Test: sinusoid"):
            if isinstance(api, str):
                self.gui_unavailable = gui.add_markdown(f"⚠ {api}")
                self.params_type = None
            else:
                self.params_type, self.sinusoid_points = api
                self._add_inputs(gui, self.params_type())
            self.gui_result = gui.add_markdown("")
        with gui.add_folder("Tracking error [mm]"):
            self.gui_plot = gui.add_uplot(
                self._plot_data(),
                self._series(),
                title="commanded − measured",
                scales={"x": {"time": False, "auto": True}, "y": {"auto": True}},
                aspect=1.6,
            )

    def _add_inputs(self, gui, defaults: Any) -> None:
        mm = lambda v: tuple(1e3 * x for x in v)  # noqa: E731
        self.gui_amplitude = gui.add_vector3("Amplitude [mm]", mm(defaults.amplitude_m), step=1.0)
        self.gui_frequency = gui.add_vector3("Frequency [Hz]", defaults.frequency_hz, step=0.1)
        self.gui_phase = gui.add_vector3(
            "Phase [deg]", tuple(math.degrees(p) for p in defaults.phase_rad), step=5.0
        )
        self.gui_offset = gui.add_vector3("Offset [mm]", mm(defaults.offset_m), step=1.0)
        self.gui_duration = gui.add_number(
            "Duration [s]", defaults.duration_s, min=0.5, max=600.0, step=0.5
        )
        self.gui_feedforward = gui.add_checkbox("Feed-forward", defaults.feedforward)
        self.gui_preview = gui.add_button("Preview path", icon=viser.Icon.ROUTE)
        self.gui_start = gui.add_button("Start", color="green", icon=viser.Icon.PLAYER_PLAY)
        self.gui_abort = gui.add_button("Abort", color="orange", icon=viser.Icon.PLAYER_STOP)
        self.gui_preview.on_click(lambda _: self.preview())
        self.gui_start.on_click(self._guard(lambda _: self.start()))
        self.gui_abort.on_click(self._guard(lambda _: self.abort()))

    def params(self) -> Any:
        """SinusoidParams (SI) from the panel's fields."""
        return self.params_type(
            amplitude_m=tuple(1e-3 * v for v in self.gui_amplitude.value),
            frequency_hz=tuple(float(v) for v in self.gui_frequency.value),
            phase_rad=tuple(math.radians(v) for v in self.gui_phase.value),
            offset_m=tuple(1e-3 * v for v in self.gui_offset.value),
            duration_s=float(self.gui_duration.value),
            feedforward=bool(self.gui_feedforward.value),
        )

    def path_of(self, params: Any) -> np.ndarray:
        """The timed part of the sinusoid, (N, 3) [m], about 100 points per second."""
        count = int(min(max(100 * params.duration_s, 50), 3000))
        return self.sinusoid_points(params, np.linspace(0.0, params.duration_s, count))

    # ---- callbacks (viser's threads) ----
    def preview(self) -> None:
        if self.params_type is None:
            return
        self.show_path(self.path_of(self.params()))
        self.message = "preview: the path drawn in purple"

    def start(self) -> None:
        runs = self.runs() if self.params_type is not None else None
        if runs is None:
            self.message = "test runs are not available"
            return
        params = self.params()
        try:
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

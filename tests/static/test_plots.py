"""The plots and the runs table as an operator reads them, in Debian's chromium against
`deltadash serve` on the simulator (no 3D scene) with three runs saved beforehand. The plots
live in their own frame (plots.html): ``plots`` is that frame, ``page`` the dashboard.

Plots: pause freezes what is drawn while the server's loop goes on and resume continues;
the cursor readout gives the drawn values at the hovered time; a drag zooms a time range and
a double-click restores the window; the snapshot is a PNG download; the window select sets
the span. Runs: the loop-health flag with its reasons as tooltip, the report in a lightbox
(no download) closed by a click outside or Esc, and the files column inside 1280x800 and
1366x768 viewports. Every wait is a condition.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.runs.logs import read_csv_rows
from tests.support.browser import (
    PAGE_WAIT_S,
    PATIENT_SIM_ENV,
    box_of,
    browser_skip_reason,
    dashboard_page,
    frame_pixel,
    page_condition,
    plots_frame,
    save_artifact,
)
from tests.support.saved_runs import HEALTHY, UNHEALTHY, save_run, synthetic_rows
from tests.support.server import Server, serve, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
QUIET = "20261130-101010-aaaa"
LOADED = "20261130-111111-bbbb"
OLD = "20261130-090909-cccc"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
DRAWN = (
    "(() => { const p = document.getElementById('plot');"
    " return JSON.stringify(p.data ? p.data.map((d) => [d.x, d.y]) : null); })()"
)


def _report_png(path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4, 3), dpi=50)
    ax.plot([0, 1], [0, 1])
    fig.savefig(path, format="png")
    plt.close(fig)


RUNS: dict[str, Path] = {}  # run id -> its folder (the saved runs' logs)


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[Server]:
    folder = tmp_path_factory.mktemp("plots")
    runs = folder / "runs"
    for run_id, health in ((QUIET, HEALTHY), (LOADED, UNHEALTHY), (OLD, None)):
        run = save_run(runs, run_id, synthetic_rows(), health)
        RUNS[run_id] = run.folder
        _report_png(run.folder / "report.png")
        run.has_report = True
        run.save()
    with serve(folder, **PATIENT_SIM_ENV) as served:
        yield served


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    with dashboard_page(server) as page:
        yield page


@pytest.fixture(scope="module")
def plots(page: Any) -> Any:
    frame = plots_frame(page)
    page_condition(
        frame, "() => window.deltadashPlot && window.deltadashPlot.fullDraws > 0", "a first plot"
    )
    return frame


HOVER_PX = 2.5  # how far from the pointer the nearest drawn sample may lie [px]

READOUT = """() => {
  const out = document.getElementById("plot-readout");
  const values = Object.fromEntries(
    [...out.querySelectorAll("output[data-series]")].map((o) => [o.dataset.series, o.textContent]));
  return { ...values, time_s: out.dataset.t, index: out.dataset.index };
}"""


def drawn(plots: Any) -> Any:
    return json.loads(plots.evaluate(DRAWN))


def paused(plots: Any) -> bool:
    return bool(plots.evaluate("window.deltadashPlot.paused"))


def set_paused(plots: Any, want: bool) -> None:
    """Pause or resume; a pause returns once what is shown is final (a draw begun before
    the pause may still finish and change it: the pause's own draw comes after it)."""
    draws = plots.evaluate("window.deltadashPlot.pausedDraws")
    if paused(plots) != want:
        plots.click("#plot-pause")
    wait_for(lambda: paused(plots) == want, f"the plots {'paused' if want else 'running'}")
    if want:
        page_condition(
            plots, f"() => window.deltadashPlot.pausedDraws > {draws}", "the paused plot drawn"
        )


def x_range(plots: Any) -> list[float]:
    return plots.evaluate("document.getElementById('plot').layout.xaxis.range")


def pixel_of(plots: Any, t: float) -> tuple[float, float]:
    """The page pixel of time ``t`` [s] half-way up the first subplot (the plots' frame
    scrolled into view: panels above it, e.g. the first-steps guidance, can push it below
    the fold)."""
    plots.frame_element().evaluate("e => e.scrollIntoView({block: 'center'})")
    x, y = plots.evaluate(
        """(t) => {
          const p = document.getElementById('plot');
          const r = p.getBoundingClientRect();
          const xa = p._fullLayout.xaxis, ya = p._fullLayout.yaxis;
          return [r.left + xa._offset + xa.l2p(t), r.top + ya._offset + ya._length / 2];
        }""",
        t,
    )
    return frame_pixel(plots, x, y)


@pytest.fixture(autouse=True)
def live_plot(plots: Any) -> Iterator[None]:
    """Each test starts (and leaves) the plots live, unzoomed, on the 10 s window: one that
    fails half-way must not leave the shared page paused for the next."""

    def reset() -> None:
        if plots.locator("#plot-live").is_visible():  # a replay left on: back to live
            plots.click("#plot-live")
            wait_for(lambda: plots.evaluate("window.deltadashPlot.replay") is None, "live plots")
        for select, value in (("#plot-signals", "position"), ("#plot-yzoom", "1")):
            if plots.locator(select).input_value() != value:
                plots.select_option(select, value)
        set_paused(plots, False)
        if plots.locator("#plot-window").input_value() != "10":
            plots.select_option("#plot-window", "10")
        wait_for(
            lambda: x_range(plots) == [-10, 0], "the live 10 s window", seen=lambda: x_range(plots)
        )

    reset()
    yield
    reset()


def test_pause_freezes_the_plot_and_resume_continues(plots: Any, server: Server) -> None:
    set_paused(plots, True)
    page_condition(plots, "() => window.deltadashPlot.dropped > 0", "samples arriving while paused")
    first = drawn(plots)
    start = server.get("/api/status")["time_s"]
    wait_for(lambda: server.get("/api/status")["time_s"] > start + 0.5, "the loop to go on")
    dropped = plots.evaluate("window.deltadashPlot.dropped")
    page_condition(plots, f"() => window.deltadashPlot.dropped > {dropped}", "more samples dropped")
    assert drawn(plots) == first, "the plot changed while paused"
    assert plots.locator("#plot-pause").inner_text() == "Resume"
    assert "paused" in plots.locator("#plot-state").inner_text()
    set_paused(plots, False)
    wait_for(lambda: drawn(plots) != first, "the plot to move on after resume")
    assert plots.locator("#plot-pause").inner_text() == "Pause"


def test_the_cursor_reads_out_the_drawn_values_at_the_hovered_time(plots: Any, page: Any) -> None:
    set_paused(plots, False)
    wait_for(lambda: min(drawn(plots)[0][0]) < -3.5, "samples drawn at t = -3 s", PAGE_WAIT_S)
    set_paused(plots, True)
    data = drawn(plots)
    readout = plots.locator("#plot-readout")
    # the drawn sample nearest -3 s: hovered there, it is the nearest to the pointer even
    # where a loaded machine left a gap in the samples around -3 s (CI once drew none
    # between -3.5 and -2.49 s); any sample well inside the 10 s window will do
    times = data[0][0]
    target = min(times, key=lambda x: abs(x - -3.0))
    assert -9.0 < target < -1.0, (target, times)
    last: dict[str, Any] = {"target": target}

    def hovered() -> bool:
        x, y = pixel_of(plots, target)
        page.mouse.move(x - 1, y)  # a move per try: a busy frame may miss one
        page.mouse.move(x, y)
        shown = readout.get_attribute("data-t")
        last.update(pixel=(x, y), shown=shown, plot=plots.evaluate("window.deltadashPlot"))
        if shown is None:
            return False
        # the readout is the drawn sample nearest the pointer: the target, or (where a loaded
        # machine left samples sparse) a neighbour at most a pixel or two away; a layout that
        # moved between reading the pixel and the move hovers elsewhere: again
        last["off_px"] = abs(pixel_of(plots, float(shown))[0] - x)
        return last["off_px"] <= HOVER_PX

    wait_for(hovered, f"the cursor readout at t = {target:.3f} s", PAGE_WAIT_S, seen=lambda: last)
    # read in one go: a hover the frame handles late may rewrite the readout between reads
    shown = plots.evaluate(READOUT)
    t, j = float(shown["time_s"]), int(shown["index"])
    assert shown["t"] == f"{t:.2f}"  # the time shown [s before now]
    assert abs(pixel_of(plots, t)[0] - pixel_of(plots, target)[0]) <= HOVER_PX, (t, target)
    assert data[0][0][j] == pytest.approx(t)
    # each series' readout is its drawn value at that sample (goal, measured, error per axis)
    for i, key in enumerate(f"{k}_{a}" for a in "xyz" for k in ("goal", "measured", "error")):
        value = data[i][1][j]
        assert shown[key] == ("–" if value is None else f"{value:.2f}"), (key, shown, value)
    # the cursor line stands at the read-out time in the first column
    # (a redraw after the pause may re-lay the plot out: the line follows its time)
    line = plots.locator("#plot .plot-cursor").first
    where: dict[str, Any] = {}

    def at_time() -> bool:
        where["line"] = line.bounding_box() if line.is_visible() else None
        where["time"] = pixel_of(plots, t)[0]
        return where["line"] is not None and abs(where["line"]["x"] - where["time"]) <= 2

    wait_for(at_time, f"the cursor line at t = {t} s", seen=lambda: where)
    save_artifact("plots-cursor.png", page.screenshot())
    set_paused(plots, False)


def test_a_drag_zooms_a_time_range_and_double_click_restores(plots: Any, page: Any) -> None:
    wait_for(lambda: x_range(plots) == [-10, 0], "the whole 10 s window")
    x0, y = pixel_of(plots, -6.0)
    x1, _ = pixel_of(plots, -2.0)
    page.mouse.move(x0, y)
    page.mouse.down()
    page.mouse.move((x0 + x1) / 2, y, steps=4)
    page.mouse.move(x1, y, steps=4)
    page.mouse.up()

    def zoomed() -> list[float] | None:
        lo, hi = x_range(plots)
        return [lo, hi] if hi - lo < 9 else None

    lo, hi = wait_for(zoomed, "the x range to narrow to the dragged range")
    assert lo == pytest.approx(-6.0, abs=0.2) and hi == pytest.approx(-2.0, abs=0.2)
    assert paused(plots), "zooming pauses the plot"
    # the other subplots follow the same time range
    assert plots.evaluate(
        "document.getElementById('plot')._fullLayout.xaxis5.range"
    ) == pytest.approx([lo, hi])
    save_artifact("plots-zoomed.png", page.locator("section.plots").screenshot())
    tries = {"double-clicks": 0, "at": -math.inf}

    def restored() -> bool:
        """The whole window back; else a double-click every 3 s (on a loaded machine the
        frame can take the two clicks further apart than plotly's double-click time)."""
        if x_range(plots) == [-10, 0]:
            return True
        if time.monotonic() - tries["at"] >= 3.0:
            page.mouse.dblclick(*pixel_of(plots, -4.0))
            tries["double-clicks"] += 1
            tries["at"] = time.monotonic()
        return False

    wait_for(restored, "the window restored by a double-click", PAGE_WAIT_S, seen=lambda: tries)
    wait_for(lambda: not paused(plots), "the plot live again (the zoom had paused it)")


def test_snapshot_downloads_a_png(plots: Any, page: Any) -> None:
    with page.expect_download() as info:
        plots.click("#plot-snapshot")
    download = info.value
    assert download.suggested_filename.endswith(".png")
    data = Path(download.path()).read_bytes()
    assert data[:8] == PNG_MAGIC
    save_artifact("plots-snapshot.png", data)


def test_the_window_select_sets_the_span(plots: Any) -> None:
    plots.select_option("#plot-window", "30")
    wait_for(lambda: x_range(plots) == [-30, 0], "a 30 s x range")
    assert "last 30 s" in plots.locator("#plots-title").inner_text()
    # samples older than 10 s are drawn once the frame has seen them (the rings keep 60 s)
    wait_for(lambda: min(drawn(plots)[0][0]) < -12, "samples older than 10 s drawn", timeout_s=120)
    plots.select_option("#plot-window", "5")
    wait_for(lambda: x_range(plots) == [-5, 0], "a 5 s x range")
    wait_for(lambda: min(drawn(plots)[0][0]) >= -5.2, "only the last 5 s drawn")
    plots.select_option("#plot-window", "10")
    wait_for(lambda: x_range(plots) == [-10, 0], "back to 10 s")


def test_each_run_shows_its_loop_health_as_a_flag_with_reasons(page: Any) -> None:
    row = lambda run_id: page.locator(f"tr[data-run='{run_id}']")  # noqa: E731
    wait_for(lambda: row(OLD).count() == 1, "the runs table")
    bad = row(LOADED).locator("td.health .flag")
    assert "bad" in bad.get_attribute("class").split()
    assert UNHEALTHY["reasons"][0] in bad.get_attribute("title")
    good = row(QUIET).locator("td.health .flag")
    assert "ok" in good.get_attribute("class").split() and good.inner_text() == "ok"
    assert "not checked" in row(OLD).locator("td.health .flag").get_attribute("title")
    colours = {
        r: row(r).locator("td.health .flag").evaluate("e => getComputedStyle(e).backgroundColor")
        for r in (QUIET, LOADED, OLD)
    }
    assert len(set(colours.values())) == 3, colours


def test_the_report_opens_in_a_lightbox_not_a_download(page: Any, server: Server) -> None:
    downloads: list[Any] = []
    page.on("download", lambda d: downloads.append(d))
    pages_before = len(page.context.pages)
    link = page.locator(f"tr[data-run='{QUIET}'] a.report")
    wait_for(lambda: link.count() == 1, "the report link")
    link.click()
    box = page.locator("#report-box")
    wait_for(box.is_visible, "the lightbox")
    page_condition(
        page, "() => document.getElementById('report-img').naturalWidth > 0", "the report image"
    )
    src = page.locator("#report-img").get_attribute("src")
    assert src.endswith(f"/api/runs/{QUIET}/report.png")
    save_artifact("plots-report-lightbox.png", page.screenshot())
    # a click outside the image (the backdrop) closes it
    page.mouse.click(5, 5)
    wait_for(lambda: not box.is_visible(), "the lightbox closed by a click outside")
    # Esc closes it too (and, being the e-stop key, e-stops: reset afterwards)
    link.click()
    wait_for(box.is_visible, "the lightbox again")
    page.keyboard.press("Escape")
    wait_for(lambda: not box.is_visible(), "the lightbox closed by Esc")
    wait_for(lambda: server.get("/api/status")["estopped"], "Esc to e-stop as everywhere")
    page.click("#reset")
    wait_for(lambda: not server.get("/api/status")["estopped"], "the page's Reset to clear it")
    assert not downloads, downloads
    assert len(page.context.pages) == pages_before, "a new tab opened"


@pytest.mark.parametrize("size", [(1280, 800), (1366, 768)])
def test_the_files_column_is_fully_visible(page: Any, size: tuple[int, int]) -> None:
    width, height = size
    page.set_viewport_size({"width": width, "height": height})
    try:
        cell = page.locator(f"tr[data-run='{LOADED}'] td.files")
        wait_for(lambda: cell.locator("a").count() == 4, "the four file links")

        def inside() -> str | None:
            """None when every link lies inside the panel and the viewport, else why not."""
            panel = page.locator("section.runs").evaluate(
                "e => { const r = e.getBoundingClientRect();"
                " return {left: r.left, right: r.right, scroll: e.scrollWidth - e.clientWidth}; }"
            )
            if panel["scroll"] > 0:
                return f"the runs panel scrolls sideways by {panel['scroll']} px"
            right = min(panel["right"], width)
            for link in cell.locator("a").all():
                b = link.bounding_box()
                if b is None or b["x"] < panel["left"] or b["x"] + b["width"] > right:
                    return f"{link.inner_text()} at {b}, panel {panel}, viewport {width}"
            return None

        box_of(cell, "the files cell")
        # the table is redrawn as runs are polled: a link between two draws has no box yet
        last: dict[str, str | None] = {}

        def fits() -> bool:
            try:  # the row is re-drawn each poll: scroll whichever is there now
                cell.evaluate("e => e.scrollIntoView({block: 'center'})", timeout=5_000)
            except Exception as exc:  # between two draws: no row to scroll this time
                last["why"] = f"not scrolled into view: {exc}"
                return False
            last["why"] = inside()
            return last["why"] is None

        wait_for(fits, "every file link inside the runs panel", seen=lambda: last["why"])
        save_artifact(f"plots-runs-{width}x{height}.png", page.locator("section.runs").screenshot())
    finally:
        page.set_viewport_size({"width": 1366, "height": 900})


def layout_of(plots: Any) -> dict[str, Any]:
    """What the tracking plots show now: y titles, trace names and visibility, y ranges."""
    return plots.evaluate(
        """() => { const p = document.getElementById('plot'); const l = p.layout;
          const y = (n) => l['yaxis' + (n === 1 ? '' : n)];
          return { titles: [1, 2, 3, 4, 5, 6].map((n) => y(n).title.text),
                   ranges: [1, 2, 3, 4, 5, 6].map((n) => y(n).range),
                   names: p.data.map((d) => d.name),
                   visible: p.data.map((d) => d.visible !== false), x: l.xaxis.range }; }"""
    )


def test_choosing_the_signals_changes_the_traces(plots: Any, page: Any) -> None:
    plots.select_option("#plot-signals", "joints")
    wait_for(lambda: layout_of(plots)["titles"][0] == "q1 [°]", "the joints' plots")
    shown = layout_of(plots)
    assert shown["titles"] == [
        "q1 [°]",
        "q2 [°]",
        "q3 [°]",
        "error q1 [°]",
        "error q2 [°]",
        "error q3 [°]",
    ]
    assert shown["names"][:3] == ["commanded", "measured", "error"]
    wait_for(lambda: any(v is not None for v in drawn(plots)[1][1]), "measured joint angles drawn")
    set_paused(plots, True)
    data = drawn(plots)
    # per joint: the error is commanded - measured at every drawn sample [deg]
    for joint in range(3):
        commanded, measured, error = (data[3 * joint + k][1] for k in range(3))
        for c, m, e in zip(commanded, measured, error, strict=True):
            if None not in (c, m, e):
                assert e == pytest.approx(c - m, abs=2e-3)
    assert "joints" in plots.locator("#plots-title").inner_text().lower()
    save_artifact("plots-joints.png", page.locator("#plots-frame").screenshot())
    set_paused(plots, False)
    plots.select_option("#plot-signals", "servos")
    wait_for(lambda: layout_of(plots)["titles"][0] == "leg 1 current [A]", "the servos' plots")
    shown = layout_of(plots)
    assert shown["titles"][3] == "leg 1 PWM [%]"
    assert shown["visible"][:3] == [False, True, True]  # no goal trace for a current
    plots.select_option("#plot-signals", "position")
    wait_for(lambda: layout_of(plots)["titles"][0] == "x [mm]", "the position plots again")


def test_the_xy_path_draws_the_same_samples_as_the_position_plots(plots: Any, page: Any) -> None:
    wait_for(lambda: len(drawn(plots)[0][0]) > 20, "samples drawn")
    set_paused(plots, True)
    page_condition(plots, "() => window.deltadashXY.frames > 0", "the XY path drawn")
    data = drawn(plots)
    xy = plots.evaluate(
        "document.getElementById('plot-xy').data.map((d) => [Array.from(d.x), Array.from(d.y)])"
    )
    # trace order: per axis goal, measured, error; the XY path is (x, y) of goal and measured
    assert xy[0] == [data[0][1], data[3][1]]
    assert xy[1] == [data[1][1], data[4][1]]
    save_artifact("plots-xy.png", page.locator("#plots-frame").screenshot())
    set_paused(plots, False)


def test_y_zoom_narrows_the_y_range_about_its_middle(plots: Any) -> None:
    set_paused(plots, True)
    fit = layout_of(plots)["ranges"]
    plots.select_option("#plot-yzoom", "5")

    def zoomed() -> list[list[float]] | None:
        ranges = layout_of(plots)["ranges"]
        return ranges if ranges != fit else None

    ranges = wait_for(zoomed, "the y ranges zoomed")
    for before, after in zip(fit, ranges, strict=True):
        assert after[1] - after[0] == pytest.approx((before[1] - before[0]) / 5)
        assert sum(after) / 2 == pytest.approx(sum(before) / 2)
    assert plots.evaluate("window.deltadashPlot.yZoom") == 5
    plots.select_option("#plot-yzoom", "1")
    wait_for(lambda: layout_of(plots)["ranges"] == fit, "the fitted y ranges again")
    set_paused(plots, False)


def test_a_five_minute_window_draws_at_most_600_points_per_trace(plots: Any) -> None:
    plots.select_option("#plot-window", "300")
    wait_for(lambda: x_range(plots) == [-300, 0], "a 5 min x range")
    assert "last 5 min" in plots.locator("#plots-title").inner_text()
    samples = plots.evaluate("window.deltadashPlot.samples")
    page_condition(
        plots, f"() => window.deltadashPlot.samples > {samples + 20}", "more samples arriving"
    )
    wait_for(lambda: len(drawn(plots)[0][0]) > 0, "samples drawn in the 5 min window")
    assert all(len(trace[0]) <= 601 for trace in drawn(plots))
    # every 10th sample (5 min at 50 Hz in at most 600 points), so the points are sparser
    assert plots.evaluate("window.deltadashPlot.windowS") == 300


def _open_report(page: Any, run_id: str) -> Any:
    link = page.locator(f"tr[data-run='{run_id}'] a.report")
    wait_for(lambda: link.count() == 1, "the report link")
    link.click()
    box = page.locator("#report-box")
    wait_for(box.is_visible, "the lightbox")
    return box


def test_a_recorded_run_replays_in_the_plots_with_its_logged_values(plots: Any, page: Any) -> None:
    rows = read_csv_rows(RUNS[LOADED] / "log.csv")
    _open_report(page, LOADED)
    page.click("#report-replay")
    wait_for(lambda: not page.locator("#report-box").is_visible(), "the lightbox closed")
    wait_for(
        lambda: (plots.evaluate("window.deltadashPlot.replay") or {}).get("run_id") == LOADED,
        "the replay of the run",
    )
    wait_for(lambda: x_range(plots) == [rows[0]["t_s"], rows[-1]["t_s"]], "the run's time range")
    assert LOADED in plots.locator("#plots-title").inner_text()
    assert plots.locator("#plot-live").is_visible()
    by_time = {round(r["t_s"], 9): r for r in rows}
    data = drawn(plots)
    assert len(data[0][0]) == len(rows)  # 340 ticks: all of them, under every cap
    for i, (column, kind) in enumerate(
        (a, k) for a in "xyz" for k in ("goal", "measured", "error")
    ):
        for t, value in zip(*data[i], strict=True):
            row = by_time[round(t, 9)]  # a drawn time is a logged tick's time
            want = (
                row[f"goal_{column}_m"] - row[f"measured_{column}_m"]
                if kind == "error"
                else row[f"{kind}_{column}_m"]
            )
            assert value == pytest.approx(want * 1e3, abs=1.5e-3), (kind, column, t)
    # the XY path replays the logged x, y too
    page_condition(plots, "() => window.deltadashXY.frames > 0", "the XY path drawn")
    xy = plots.evaluate("Array.from(document.getElementById('plot-xy').data[1].x)")
    assert xy == pytest.approx([r["measured_x_m"] * 1e3 for r in rows], abs=1.5e-3)
    # live samples are not mixed in: the drawn data stays the run's
    dropped = plots.evaluate("window.deltadashPlot.dropped")
    page_condition(
        plots, f"() => window.deltadashPlot.dropped > {dropped + 10}", "live samples dropped"
    )
    assert drawn(plots) == data
    plots.select_option("#plot-signals", "servos")
    wait_for(lambda: "no servo current" in plots.locator("#plot-state").inner_text(), "the note")
    plots.select_option("#plot-signals", "position")
    save_artifact("plots-replay.png", page.locator("#plots-frame").screenshot())
    plots.click("#plot-live")
    wait_for(lambda: x_range(plots) == [-10, 0], "the live window again")
    assert plots.evaluate("window.deltadashPlot.replay") is None


def test_the_interactive_report_draws_the_runs_logged_values(page: Any) -> None:
    rows = read_csv_rows(RUNS[QUIET] / "log.csv")
    box = _open_report(page, QUIET)
    page.click("#report-interactive")

    def report() -> Any:
        page.evaluate("0")
        frame = next((f for f in page.frames if "/report.html" in f.url), None)
        try:
            return frame if frame and frame.evaluate("window.deltadashReport.drawn") else None
        except Exception:  # its document not there yet
            return None

    frame = wait_for(report, "the interactive report drawn", PAGE_WAIT_S)
    assert not page.locator("#report-img").is_visible()
    data = frame.evaluate(
        "document.getElementById('ir-plot').data.map((d) => [Array.from(d.x), Array.from(d.y)])"
    )
    assert data[0][0] == pytest.approx([r["t_s"] for r in rows])
    assert data[0][1] == pytest.approx([r["goal_x_m"] * 1e3 for r in rows], abs=1.5e-3)
    assert data[1][1] == pytest.approx([r["measured_x_m"] * 1e3 for r in rows], abs=1.5e-3)
    assert QUIET in frame.locator("#ir-title").inner_text()
    assert "RMSE" in frame.locator("#ir-summary").inner_text()
    # values under the pointer: plotly's hover label at a tick's time
    t = rows[200]["t_s"]
    last: dict[str, Any] = {}

    def hover_label() -> bool:
        x, y = frame.evaluate(
            """(t) => { const p = document.getElementById('ir-plot');
              const r = p.getBoundingClientRect();
              const xa = p._fullLayout.xaxis, ya = p._fullLayout.yaxis;
              return [r.left + xa._offset + xa.l2p(t), r.top + ya._offset + ya._length / 2]; }""",
            t,
        )
        px, py = frame_pixel(frame, x, y)
        page.mouse.move(px - 1, py)
        page.mouse.move(px, py)
        last["text"] = frame.evaluate(
            "Array.from(document.querySelectorAll('.hoverlayer .hovertext'))"
            ".map((e) => e.textContent)"
        )
        return any("measured x" in text for text in last["text"])

    wait_for(hover_label, "a hover label with the measured x", PAGE_WAIT_S, seen=lambda: last)
    save_artifact("plots-interactive-report.png", page.screenshot())
    page.click("#report-interactive")  # back to the image
    wait_for(lambda: page.locator("#report-img").is_visible(), "the PNG again")
    page.click("#report-close")
    wait_for(lambda: not box.is_visible(), "the lightbox closed")


def test_the_drone_attitude_is_roll_pitch_yaw_of_its_quaternion(plots: Any) -> None:
    """The drone pose set's attitude [rad, converted to deg when drawn] from the pose's
    quaternion (w, x, y, z): hand-computed turns about one axis each, and none."""
    half = 0.5 * math.radians(30)
    cases = {
        (1.0, 0.0, 0.0, 0.0): (0.0, 0.0, 0.0),
        (math.cos(half), math.sin(half), 0.0, 0.0): (30.0, 0.0, 0.0),
        (math.cos(half), 0.0, math.sin(half), 0.0): (0.0, 30.0, 0.0),
        (math.cos(half), 0.0, 0.0, math.sin(half)): (0.0, 0.0, 30.0),
    }
    for quaternion, want in cases.items():
        got = plots.evaluate(
            "(q) => import('/js/plots.js').then((m) => m.attitude(...q))", list(quaternion)
        )
        assert [math.degrees(v) for v in got] == pytest.approx(want, abs=1e-9), quaternion

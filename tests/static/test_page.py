"""The dashboard in Debian's chromium against `deltadash serve` on the simulator.

One page is walked through in order, as an operator would: the header fills in, go-to,
jog by key and by pad, a short sinusoid (plot data grows, the run lands in the table with
stats), a longer one through a reload (the bar and the form come back from the server), the
two compared, e-stop by key, then the server dies and the page says so. Screenshots go to
artifacts/ (git-ignored); the plot's frame rate is written there too, not asserted.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlsplit

import pytest

from tests.support import wait as waiting
from tests.support.browser import (
    PAGE_WAIT_S,
    browser_skip_reason,
    dashboard_page,
    page_condition,
    plots_frame,
    save_artifact,
    toasts,
)
from tests.support.server import Server, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
STEP_M = 0.005  # how far a held jog must go before the test lets go


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    with dashboard_page(server) as page:
        yield page


def until(
    server: Server, condition: Any, what: str, timeout_s: float = 60.0, page: Any = None
) -> Any:
    """wait_for on the robot: a timeout prints the server's mode, faults and points (and the
    page's toast, given the page)."""

    def seen() -> dict[str, Any]:
        brief = server.brief()
        if page is not None:
            brief["messages"] = toasts(page)
        return brief

    return wait_for(condition, what, timeout_s, seen=seen)


def measured(server: Server) -> list[float]:
    return server.get("/api/status")["ee"]["position_m"]


def commanded_still(server: Server) -> list[float] | None:
    """The commanded point once two reads 0.2 s of loop time apart agree; None if moving."""
    first = server.get("/api/status")
    wait_for(lambda: server.get("/api/status")["time_s"] > first["time_s"] + 0.2, "loop time")
    now = server.get("/api/status")["ee"]["commanded_m"]
    return now if now == first["ee"]["commanded_m"] else None


def shot(page: Any, name: str) -> None:
    page.evaluate("window.scrollTo(0, 0)")  # the sticky header belongs at the top
    save_artifact(f"dashboard-{name}.png", page.screenshot(full_page=True))


def text(page: Any, selector: str) -> str:
    return page.locator(selector).inner_text()


def test_header_fills_in_from_the_server(page: Any, server: Server) -> None:
    wait_for(lambda: text(page, "#conn") == "connected", "the link to show connected")
    status = server.get("/api/status")
    wait_for(lambda: "Hz" in text(page, "#loop"), "the loop rate")
    assert text(page, "#mode").startswith(status["mode"])
    assert status["backend_description"] in text(page, "#backend")
    assert page.locator("#estop").is_visible()
    info = server.get("/api/info")
    scene_url = f":{info['viser_port']}/"
    assert page.locator("#scene-link").get_attribute("href").endswith(scene_url)
    # headless chromium renders WebGL in software: the scene is offered, not embedded
    assert not page.locator("#scene-embed").is_checked()
    page.check("#scene-embed")
    # embedded under software WebGL at half resolution (viser's fixedDpr): a quarter of the
    # pixels for the CPU to draw
    frame_url = urlsplit(page.locator("#scene").get_attribute("src"))
    assert f":{frame_url.port}/" == scene_url and frame_url.query == "fixedDpr=0.5"
    assert page.locator("#scene").is_visible() and not page.locator("#scene-note").is_visible()
    wait_for(lambda: page.locator("#servo-rows tr").count() == 3, "three servo rows")
    shot(page, "loaded")


def test_go_to_then_jog_by_key_and_by_pad(page: Any, server: Server) -> None:
    # clicked until accepted: the twin's arm may still swing past its joint limits
    until(
        server, lambda: server.get("/api/status")["torque"] or page.click("#torque-on"), "torque on"
    )
    # the form follows the robot until typed in (issue 32): type the goal (0, 0, -240) mm
    for name, value in zip("xyz", ("0", "0", "-240"), strict=True):
        page.fill(f"#goal-form input[name={name}]", value)
    page.click("#goal-form button[type=submit]")

    def arrived_or_confirmed() -> bool:  # from the hanging arm it is a long move: confirm it
        if page.locator("#confirm").is_visible():
            page.click("#confirm-yes")
        return abs(measured(server)[2] + 0.24) < 0.002

    until(server, arrived_or_confirmed, "arrival at z = -240 mm")
    shown = text(page, "#pos-meas")

    page.check("#jog-keys")  # hold-to-move: it jogs while the key is down, stops on release
    x_before = measured(server)[0]
    page.keyboard.down("ArrowRight")
    until(server, lambda: measured(server)[0] > x_before + STEP_M, "+x while the arrow key is held")
    page.keyboard.up("ArrowRight")
    until(server, lambda: commanded_still(server), "the jog to stop when the key is released")
    wait_for(lambda: text(page, "#pos-meas") != shown, "the page's measured position to change")

    z_before = measured(server)[2]
    page.hover("[data-jog='z+']")
    page.mouse.down()
    until(
        server, lambda: measured(server)[2] > z_before + STEP_M, "+z while the pad button is held"
    )
    page.mouse.up()
    until(server, lambda: commanded_still(server), "the jog to stop when the button is released")
    shot(page, "jogged")


def test_a_held_jog_stops_by_itself_when_the_link_is_lost(page: Any, server: Server) -> None:
    """The killed client: heartbeats stop reaching the server while the key is still down."""
    page.check("#jog-keys")
    x_before = measured(server)[0]
    page.keyboard.down("ArrowLeft")
    until(server, lambda: measured(server)[0] < x_before - 0.002, "-x while the key is held")
    page.route("**/api/jog", lambda route: route.abort())  # the link drops mid-jog
    try:
        stopped = until(
            server, lambda: commanded_still(server), "the server to stop the jog itself"
        )
        assert "no heartbeat" in (server.get("/api/status")["notice"] or "")
        assert server.get("/api/status")["ee"]["commanded_m"] == stopped
    finally:
        page.keyboard.up("ArrowLeft")
        page.unroute("**/api/jog")


def test_keys_do_not_jog_while_keyboard_jog_is_off(page: Any, server: Server) -> None:
    page.uncheck("#jog-keys")
    goal = server.get("/api/status")["goal"]["position_m"]
    page.keyboard.press("ArrowUp")
    page.wait_for_timeout(500)  # a refused jog has no effect to wait for; give it a chance
    assert server.get("/api/status")["goal"]["position_m"] == goal


FAKE_PAD = """(state) => {
  const buttons = Array.from({ length: 8 }, (_, i) => ({ pressed: i === 4 && state.held }));
  const pad = { id: "test pad", axes: [state.x, 0, 0, 0], buttons };
  Object.defineProperty(navigator, "getGamepads", { configurable: true, value: () => [pad] });
}"""


def test_gamepad_jogs_only_with_the_deadman_held(page: Any, server: Server) -> None:
    page.check("#jog-pad")
    page.evaluate(FAKE_PAD, {"x": 1.0, "held": False})
    wait_for(lambda: "hold LB" in text(page, "#gamepad-state"), "the page to see the pad")
    goal = server.get("/api/status")["goal"]["position_m"]
    page.wait_for_timeout(500)  # stick full right, deadman released: nothing may move
    assert server.get("/api/status")["goal"]["position_m"] == goal

    page.evaluate(FAKE_PAD, {"x": 1.0, "held": True})
    until(
        server,
        lambda: server.get("/api/status")["goal"]["position_m"][0] > goal[0] + 0.002,
        "+x goal from the stick with the deadman held",
    )
    page.evaluate(FAKE_PAD, {"x": 1.0, "held": False})
    page.uncheck("#jog-pad")


def test_plot_buffer_keeps_a_fixed_window_in_order(page: Any) -> None:
    """The ring buffer behind the plots: after an hour's worth of pushes, the last N in order."""
    result = page.evaluate("""async () => {
        const { Ring } = await import("/js/ring.js");
        const ring = new Ring(500);
        for (let i = 0; i < 50 * 3600; i++) ring.push(i);
        ring.push(null);
        const view = ring.view(), values = ring.values();
        return { length: view.length, first: view[0], last: values[values.length - 1],
                 before: values[values.length - 2], stored: ring.data.length };
    }""")
    assert result == {
        "length": 500,
        "first": 50 * 3600 - 499,
        "last": None,
        "before": 50 * 3600 - 1,
        "stored": 1000,
    }


def plotted_span_mm(page: Any) -> float:
    """Peak-to-peak of the measured x in the plot itself (plotly's own trace data, in the
    plots' frame) [mm]."""
    return plots_frame(page).evaluate(
        "(() => { const y = document.getElementById('plot').data[1].y.filter(v => v !== null);"
        " return Math.max(...y) - Math.min(...y); })()"
    )


def ready_to_run(page: Any, server: Server) -> None:
    """No e-stop or fault, torque on, the arm at rest: a run's own start."""
    page.click("#reset")
    until(
        server, lambda: server.get("/api/status")["mode"] in ("idle", "jog"), "no e-stop or fault"
    )
    # clicked until accepted: the twin's arm may still swing past its joint limits
    until(
        server, lambda: server.get("/api/status")["torque"] or page.click("#torque-on"), "torque on"
    )
    until(server, lambda: commanded_still(server), "the arm at rest")


def start_from_page(page: Any, server: Server) -> dict:
    """Click "Start run" until the server has the run (a starved machine may drop the
    request: 'Failed to fetch'; the server starts no run for a client that has gone)."""
    runs_before = len(server.get("/api/runs"))
    page.click("#run-start")
    toast = page.locator("#toast")

    def started() -> bool:
        text = toast.inner_text() if toast.is_visible() else ""
        if len(server.get("/api/runs")) > runs_before:
            return True
        if "Failed to fetch" in text:
            page.evaluate("document.getElementById('toast').textContent = ''")
            page.click("#run-start")
        return False

    until(
        server,
        started,
        "the run to start (a refusal shows in the toast)",
        PAGE_WAIT_S,
        page,
    )
    return server.get("/api/runs")[0]


def feasible(page: Any) -> None:
    preview = "#run-preview"
    waiting.wait_for(
        lambda: text(page, preview).rsplit(": ", 1)[-1] == "feasible",
        "the preview to say feasible",
        poll_s=0.1,
        seen=lambda: text(page, preview),
    )


def test_sinusoid_runs_plots_and_lands_in_the_table(page: Any, server: Server) -> None:
    ready_to_run(page, server)
    page.fill("#run-form input[name=duration]", "2")
    feasible(page)
    assert "peak joint speed" in text(page, "#run-preview")
    plots = plots_frame(page)
    before = plots.evaluate("window.deltadashPlot.samples")
    start_from_page(page, server)
    wait_for(lambda: plots.evaluate("window.deltadashPlot.samples") > before, "new plot samples")
    # the sinusoid's x amplitude is 50 mm: the plotted measured x must swing by tens of mm
    wait_for(lambda: plotted_span_mm(page) > 30, "the plotted x to show the sinusoid")
    shot(page, "running")
    run = wait_for(
        lambda: [r for r in server.get("/api/runs") if r["state"] != "running"],
        "the run to end",
        timeout_s=PAGE_WAIT_S,
    )[0]
    assert run["state"] == "done", run
    row = page.locator(f"tr[data-run='{run['run_id']}']")
    wait_for(lambda: row.count() == 1 and "done" in row.inner_text(), "the run's row")
    rmse_mm = run["stats"]["tracking"]["x"]["rmse_m"] * 1000
    wait_for(lambda: f"{rmse_mm:.2f}" in row.inner_text(), "the x RMSE in mm in the row")
    assert row.locator("a", has_text="CSV").get_attribute("href").endswith("/log.csv")
    stats = plots.evaluate("window.deltadashPlot")
    save_artifact("dashboard-plot.json", json.dumps(stats).encode())
    shot(page, "run-done")


def test_a_page_reloaded_mid_run_shows_its_real_progress_and_parameters(
    page: Any, server: Server
) -> None:
    ready_to_run(page, server)
    page.fill("#run-form input[name=duration]", "30")
    page.fill("#run-form input[name=amplitude0]", "30")
    feasible(page)
    run_id = start_from_page(page, server)["run_id"]

    def share() -> float:
        progress = server.get(f"/api/runs/{run_id}")["progress"] or {}
        return progress.get("test_elapsed_s", 0.0) / progress.get("test_duration_s", 1.0)

    wait_for(
        lambda: share() >= 0.3,
        "a third of the test part done",
        PAGE_WAIT_S,
        seen=lambda: {
            **{k: server.get(f"/api/runs/{run_id}")[k] for k in ("state", "progress")},
            **server.brief(),
        },
    )
    page.reload()  # the form's fields are back to their defaults (10 s, 50 mm)
    # A bar restarted at 0 on the reload stays behind the server's progress by what was
    # done before it (0.3); one that goes on from the server's figure keeps up with it.
    bar = (
        "(() => [document.getElementById('run-phase').textContent,"
        " document.getElementById('run-progress').value])()"
    )
    seen: list = []

    def keeps_up() -> bool:
        phase, value = page.evaluate(bar)
        seen[:] = [phase, value, share()]  # the server's share read after the page's
        return "timed" in phase and value >= seen[2] - 0.15

    waiting.wait_for(
        keeps_up,
        "the bar to keep up with the server's progress while the test part goes",
        timeout_s=PAGE_WAIT_S,
        poll_s=0.2,
        seen=lambda: seen,
    )
    assert page.locator("#run-form input[name=duration]").input_value() == "30"
    assert page.locator("#run-form input[name=amplitude0]").input_value() == "30"
    assert "amplitude 30 / 50 / 80 mm" in text(page, "#run-params")
    shot(page, "reloaded-mid-run")
    wait_for(
        lambda: server.get(f"/api/runs/{run_id}")["state"] != "running",
        "the run to end",
        PAGE_WAIT_S,
    )


def test_two_runs_compared_side_by_side(page: Any, server: Server) -> None:
    done = [r for r in server.get("/api/runs") if r["state"] == "done"][:2]
    assert len(done) == 2, done
    for run in done:
        box = page.locator(f"tr[data-run='{run['run_id']}'] input.pick")
        wait_for(lambda b=box: b.count() == 1 and b.is_enabled(), "the run's checkbox")
        box.check()
    wait_for(lambda: page.locator("#compare-runs").is_enabled(), "the compare button enabled")
    page.click("#compare-runs")
    ids = ",".join(run["run_id"] for run in done)
    page_condition(
        page,
        f"""() => {{ const img = document.getElementById('compare-plot');
            return !document.getElementById('compare').hidden && img.dataset.ids === '{ids}'
                && img.complete && img.naturalWidth > 0; }}""",
        "the comparison table and plot",
    )
    table = page.locator("#compare-table")
    rmse = table.locator("tr", has_text="RMSE x")
    for run in done:
        assert f"{run['stats']['tracking']['x']['rmse_m'] * 1e3:.2f}" in rmse.inner_text()
    assert "amplitude 30 / 50 / 80 mm" in table.inner_text()  # the tests in words
    shot(page, "compare")


def test_space_presses_e_stop(page: Any, server: Server) -> None:
    page.locator("h1").click()  # focus on the page, not in a field
    page.keyboard.press(" ")
    wait_for(lambda: server.get("/api/status")["estopped"], "the server to be e-stopped")
    wait_for(lambda: "estop" in text(page, "#mode"), "the header to show the e-stop")
    assert "E-stop engaged" in text(page, "#faults")
    shot(page, "estop")


def test_lost_server_shows_a_banner(page: Any, server: Server) -> None:
    server.process.terminate()
    server.process.wait(timeout=15)
    wait_for(lambda: page.locator("#banner").is_visible(), "the connection banner")
    assert "Reconnecting" in text(page, "#banner")
    assert text(page, "#conn") != "connected"
    shot(page, "offline")

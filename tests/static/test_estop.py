"""The e-stop answers in every state of the page: here the hardest one, the real 3D scene
embedded (viser drawing with software WebGL) and the plots running.

Space and a press on the E-STOP button each reach the server; the latency (the input
event's time in the page to the server's arrival time, GET /api/status
``estop_received_unix_s``) is printed, not asserted (figures: docs/dashboard.md, measured
by benchmarks/estop_latency.py). Reset brings the page back each time.

The plots run in their own frame, on another renderer main thread than the page's keys: a
press on the page reaches the server while the plots' frame is held busy (it would wait for
the frame on a shared thread), and Space pressed while the frame has the focus e-stops too.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any
from urllib.parse import urlsplit

import pytest

from tests.support.browser import (
    PAGE_WAIT_S,
    browser_skip_reason,
    dashboard_page,
    page_condition,
    plots_frame,
)
from tests.support.server import Server, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    with dashboard_page(server, stub_scene=False) as page:  # the real scene: the hard case
        yield page


def scene_frame(page: Any, viser_port: int) -> Any:
    """The embedded scene's frame once viser has put its canvas in it, else None."""
    page.evaluate("0")  # a new frame is known only after a call into Playwright
    for frame in page.frames:
        if frame == page.main_frame or urlsplit(frame.url).port != viser_port:
            continue
        try:
            if frame.evaluate("document.querySelectorAll('canvas').length > 0"):
                return frame
        except Exception:  # navigating, or not ready yet
            pass
    return None


def press_estop(page: Any, server: Server, how: str) -> float:
    """Press Space or the button once; the server must be e-stopped by it. Returns the
    latency [ms] from the input event in the page to the server's arrival time."""
    before = server.get("/api/status")
    assert not before["estopped"]
    count = page.evaluate("window.deltadash.estops.length")
    if how == "key":
        page.keyboard.press("Space")
    else:  # the button stops on press: a bare press, without Playwright's click checks
        box = page.locator("#estop").bounding_box(timeout=PAGE_WAIT_S * 1e3)
        page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.mouse.down()
        page.mouse.up()
    status = wait_for(
        lambda: (s := server.get("/api/status"))["estopped"] and s, f"the e-stop by {how}"
    )
    received = status["estop_received_unix_s"]
    assert received is not None and received != before["estop_received_unix_s"]
    record = wait_for(
        lambda: page.evaluate(f"window.deltadash.estops[{count}]"), "the page's record"
    )
    assert page.evaluate("window.deltadash.estops.length") == count + 1  # one press, one stop
    assert record["source"] == ("keydown" if how == "key" else "pointerdown")
    # the press went both ways, /api/estop and the e-stop listener's own thread, counted
    # once (the same press id): the listener's arrival is kept beside the middleware's
    assert record["paths"] == 2
    arrivals = wait_for(
        lambda: (
            (a := server.get("/api/status")["estop_arrivals_unix_s"]).keys()
            >= {"listener", "middleware"}
            and a
        ),
        f"the press by {how} through both paths",
    )
    # the status names the earliest arrival: the listener's (in the robot node) may be seen
    # a node status (0.1 s) after the middleware's, though it came first
    first = server.get("/api/status")["estop_received_unix_s"]
    assert first == min(arrivals.values()) <= received
    return first * 1e3 - record["event_unix_ms"]


def plots_running(page: Any) -> Any:
    """The plots' frame, once it draws (from another site than the page, like the scene)."""
    plots = plots_frame(page)
    assert urlsplit(plots.url).hostname != urlsplit(page.url).hostname
    page_condition(
        plots,
        "() => document.getElementById('plot-fps').textContent.trim() !== ''",
        "the plots to run",
    )
    return plots


def reset(page: Any, server: Server) -> None:
    page.click("#reset", timeout=PAGE_WAIT_S * 1e3)
    wait_for(lambda: not server.get("/api/status")["estopped"], "the reset to clear the e-stop")


def test_estop_answers_with_the_scene_embedded_and_plots_running(page: Any, server: Server) -> None:
    wait_for(lambda: page.locator("#conn").inner_text() == "connected", "the link")
    page.check("#scene-embed", timeout=PAGE_WAIT_S * 1e3)
    # the frame is from another site than the page (same machine, another name): chromium
    # gives it its own renderer process, so viser's drawing is off this page's main thread
    page_url = urlsplit(page.url)
    frame_url = urlsplit(page.locator("#scene").get_attribute("src"))
    assert frame_url.hostname != page_url.hostname
    assert frame_url.port == server.get("/api/info")["viser_port"]
    viser_port = server.get("/api/info")["viser_port"]
    wait_for(
        lambda: scene_frame(page, viser_port), "viser's canvas in the embedded scene", PAGE_WAIT_S
    )
    plots_running(page)
    latencies = {}
    for how in ("key", "button", "key"):
        latencies.setdefault(how, []).append(press_estop(page, server, how))
        wait_for(lambda: "estop" in page.locator("#mode").inner_text(), "the header's e-stop")
        reset(page, server)
    assert isinstance(server.get("/api/info")["estop_port"], int)  # the page's second path
    print(
        "e-stop latency, input event in the page -> server [ms]: "
        + ", ".join(f"{how} {', '.join(f'{v:.0f}' for v in vs)}" for how, vs in latencies.items())
    )


# The plots' frame held busy until it sees the server e-stopped (a synchronous status read
# in its busy loop), for at most ``limit_ms``: ``__busy`` says whether it saw the e-stop while
# busy, ``__busyFrom`` when the loop began [Unix ms]. (A message to the page from inside the
# loop would not do: chromium sends a cross-site postMessage after the sender's task.)
HOLD_BUSY = """(limit_ms) => {
  window.__busy = "starting";
  setTimeout(() => {
    window.__busyFrom = Date.now();
    const end = Date.now() + limit_ms;
    while (Date.now() < end) {
      const request = new XMLHttpRequest();
      request.open("GET", "/api/status", false);  // synchronous: the thread stays busy
      request.send();
      if (JSON.parse(request.responseText).estopped) { window.__busy = "saw the e-stop"; return; }
    }
    window.__busy = "gave up";
  }, 0);
}"""


def test_the_page_stops_while_the_plots_frame_is_held_busy(page: Any, server: Server) -> None:
    # the scene unloaded: it shares the plots' process (the same other site), whose thread it
    # holds for seconds at a time, so the busy loop would begin long after the key each time
    page.uncheck("#scene-embed", timeout=PAGE_WAIT_S * 1e3)
    plots = plots_running(page)
    seen = []
    for _ in range(5):  # until the key came after the loop began (it usually does at once)
        assert not server.get("/api/status")["estopped"]
        page.evaluate("window.focus()")  # the keys go to the page, not to a frame
        count = page.evaluate("window.deltadash.estops.length")
        plots.evaluate(HOLD_BUSY, 120_000)  # returns at once; the loop begins just after
        page.keyboard.press("Space")
        wait_for(lambda: server.get("/api/status")["estopped"], "the e-stop with the plots busy")
        # the frame's thread is held until its loop sees the e-stop: this read waits for that
        busy, busy_from = plots.evaluate("[window.__busy, window.__busyFrom]")
        record = page.evaluate(f"window.deltadash.estops[{count}]")
        assert record["source"] == "keydown", record
        seen.append((busy, busy_from, record["sent_unix_ms"]))
        reset(page, server)
        if record["sent_unix_ms"] >= busy_from:
            # the page handled the key while the frame's loop ran, and the loop was still
            # running when the stop arrived: two threads (one would have run them in turn)
            assert busy == "saw the e-stop", seen
            return
    raise AssertionError(f"the key was handled before the busy loop began every time: {seen}")


def test_space_while_the_plots_have_the_focus_stops(page: Any, server: Server) -> None:
    plots = plots_running(page)
    assert not server.get("/api/status")["estopped"]
    count = page.evaluate("window.deltadash.estops.length")
    pause = plots.locator("#plot-pause")
    pause.click()  # the focus is in the plots' frame now, on the Pause button
    wait_for(lambda: pause.inner_text() == "Resume", "the plots paused by the click")
    page.keyboard.press("Space")
    wait_for(lambda: server.get("/api/status")["estopped"], "the e-stop from the plots' frame")
    # the frame sent it and told the page, which recorded it and sent it by its paths too
    record = wait_for(
        lambda: page.evaluate(f"window.deltadash.estops[{count}]"), "the page's record"
    )
    assert record["source"] == "plots:keydown", record
    assert record["paths"] == 3, record  # the frame's /api/estop, the page's and the listener
    assert pause.inner_text() == "Resume", "Space clicked the focused button"
    pause.click()
    wait_for(lambda: pause.inner_text() == "Pause", "the plots running again")
    reset(page, server)

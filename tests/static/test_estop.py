"""The e-stop answers in every state of the page: here the hardest one, the real 3D scene
embedded (viser drawing with software WebGL) and the plots running.

Space and a press on the E-STOP button each reach the server; the latency (the input
event's time in the page to the server's arrival time, GET /api/status
``estop_received_unix_s``) is printed, not asserted (figures: docs/dashboard.md, measured
by benchmarks/estop_latency.py). Reset brings the page back each time.
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
)
from tests.support.server import Server, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    with dashboard_page(server, stub_scene=False) as page:  # the real scene: the hard case
        yield page


def scene_frame(page: Any) -> Any:
    """The embedded scene's frame once viser has put its canvas in it, else None."""
    for frame in page.frames:
        if frame == page.main_frame:
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
    assert server.get("/api/status")["estop_received_unix_s"] == min(arrivals.values()) == received
    return received * 1e3 - record["event_unix_ms"]


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
    wait_for(lambda: scene_frame(page), "viser's canvas in the embedded scene", PAGE_WAIT_S)
    page_condition(
        page,
        "() => document.getElementById('plot-fps').textContent.trim() !== ''",
        "the plots to run",
    )
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

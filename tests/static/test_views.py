"""The loop-health light and the 2D workspace view, in Debian's chromium against
`deltadash serve` on the simulator: the light shows the server's level and figures, the
view draws the accepted region and the robot's point, and an outside goal typed in Go-to
offers "Go to nearest", which makes the nearest reachable point the loop's setpoint."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from tests.support import wait as waiting
from tests.support.browser import (
    PAGE_WAIT_S,
    browser_skip_reason,
    dashboard_page,
    page_condition,
    save_artifact,
)
from tests.support.server import Server, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
ROBOT_RGB = (0x18, 0x64, 0xAB)  # workspace2d.js COLOURS.robot
REACHABLE_RGB = (0xD3, 0xF9, 0xD8)  # COLOURS.reachable


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    with dashboard_page(server) as page:
        yield page


def pixels_of(page: Any, canvas: str, rgb: tuple[int, int, int]) -> int:
    """How many pixels of the canvas have exactly this colour."""
    return page.evaluate(
        """([id, rgb]) => {
          const c = document.getElementById(id);
          const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
          let n = 0;
          for (let k = 0; k < d.length; k += 4) {
            if (d[k] === rgb[0] && d[k + 1] === rgb[1] && d[k + 2] === rgb[2]) n += 1;
          }
          return n;
        }""",
        [canvas, list(rgb)],
    )


def colour_at(page: Any, canvas: str) -> tuple[int, ...] | None:
    """The colour at the robot's marker (the canvas's data-robot-px), None if not drawn."""
    colour = page.evaluate(
        """(id) => {
          const c = document.getElementById(id);
          if (!c.dataset.robotPx) return null;
          const [x, y] = c.dataset.robotPx.split(",").map(Number);
          return Array.from(c.getContext("2d").getImageData(x, y, 1, 1).data.slice(0, 3));
        }""",
        canvas,
    )
    return None if colour is None else tuple(colour)


def torque_on(page: Any, server: Server) -> None:
    """Click Torque on until the server has it on (the twin's arm may still swing past its
    joint limits just after start-up), one click every 2 s at most on a slow machine."""
    clicked = [-1e9]

    def on() -> bool:
        if server.get("/api/status")["torque"]:
            return True
        if time.monotonic() - clicked[0] > 2.0:
            clicked[0] = time.monotonic()
            page.click("#torque-on")
        return False

    def seen() -> Any:
        status = server.get("/api/status")
        toast = page.locator("#toast")
        return status["mode"], status["faults"], toast.is_visible() and toast.inner_text()

    waiting.wait_for(on, "torque on", PAGE_WAIT_S, poll_s=0.2, seen=seen)


def test_the_loop_light_shows_the_servers_level_and_figures(page: Any, server: Server) -> None:
    light = page.locator("#loop-health")
    page_condition(
        page,
        "() => /health-(green|amber|red)/.test(document.getElementById('loop-health').className)",
        "the loop light to take a colour",
    )
    level = light.get_attribute("data-level")
    assert f"health-{level}" in light.get_attribute("class")
    assert light.is_visible()
    text, title = light.inner_text(), light.get_attribute("title")
    assert "Hz" in text and "p99" in text and "ovr" in text
    assert "overruns" in title and "last 10 s" in title and "amber: halfway" in title
    # the page shows the server's verdict, not one of its own (the level may change between
    # reads on a loaded machine: wait until one read agrees)
    wait_for(
        lambda: (
            server.get("/api/status")["loop"]["health"]["level"]
            == light.get_attribute("data-level")
        ),
        "the page's light to match the server's level",
    )


def test_an_outside_goal_offers_the_nearest_point_and_goes_there(page: Any, server: Server) -> None:
    # torque on where the arm hangs at power-up, (0, 0, -395) mm, just below the workspace;
    # a goal further below is outside, and its nearest reachable point is a few mm away
    torque_on(page, server)
    page.fill("#goal-form input[name=x]", "0")
    page.fill("#goal-form input[name=y]", "20")
    page.fill("#goal-form input[name=z]", "-450")
    button = page.locator("#ws-go-nearest")
    wait_for(lambda: button.is_visible(), "the Go to nearest button for an outside goal")
    assert "outside" in page.locator("#ws-typed").inner_text()
    query = "/api/workspace/nearest?x_m=0&y_m=0.02&z_m=-0.45"
    nearest = np.array(server.get(query)["nearest_m"])
    save_artifact("views-go-nearest.png", page.screenshot(full_page=True))
    button.click()

    def commanded_at_nearest() -> bool:
        status = server.get("/api/status")
        goal, commanded = status["goal"]["position_m"], status["ee"]["commanded_m"]
        return bool(
            goal is not None
            and np.allclose(goal, nearest, atol=1e-6)
            and np.allclose(commanded, nearest, atol=1e-4)
        )

    waiting.wait_for(
        commanded_at_nearest,
        "the commanded point to reach the nearest reachable point",
        seen=lambda: (server.get("/api/status")["ee"], page.locator("#toast").inner_text()),
    )
    # the form now holds the goal sent, which is inside: the offer goes away
    wait_for(lambda: not button.is_visible(), "the offer to go once the typed goal is inside")
    assert "inside" in page.locator("#ws-typed").inner_text()


def test_a_typed_goal_refused_as_busy_is_checked_again(page: Any, server: Server) -> None:
    """The workspace queries answer 503 while their workers are busy: the page asks again
    (here the first answer is a made-up 503, the second the server's own)."""
    refused: list[str] = []

    def busy_once(route: Any) -> None:
        if not refused:
            refused.append(route.request.url)
            detail = '{"detail": "busy: the server is answering other workspace queries"}'
            route.fulfill(status=503, content_type="application/json", body=detail)
        else:
            route.continue_()

    page.route("**/api/workspace/nearest?*", busy_once)
    try:
        page.fill("#goal-form input[name=x]", "0")
        page.fill("#goal-form input[name=y]", "30")
        page.fill("#goal-form input[name=z]", "-460")
        # Playwright's sync API runs the route's handler while the test is in one of its
        # calls: the condition makes one
        wait_for(lambda: page.evaluate("true") and refused, "the first check of the typed goal")
        wait_for(
            lambda: "nearest reachable" in page.locator("#ws-typed").inner_text(),
            "the typed goal checked again after the busy answer",
        )
        assert page.locator("#ws-go-nearest").is_visible()
    finally:
        page.unroute("**/api/workspace/nearest?*")


def test_the_2d_view_draws_the_region_and_the_robots_point(page: Any, server: Server) -> None:
    # the arm powers up hanging below the workspace: the top cut there is empty; go home
    torque_on(page, server)
    for axis, value in zip("xyz", ("0", "0", "-240"), strict=True):
        page.fill(f"#goal-form input[name={axis}]", value)
    page.click("#goal-form button[type=submit]")

    def arrived_or_confirmed() -> bool:  # from the hanging arm it is a long move: confirm it
        if page.locator("#confirm").is_visible():
            page.click("#confirm-yes")
        return abs(server.get("/api/status")["ee"]["position_m"][2] + 0.24) < 0.002

    wait_for(arrived_or_confirmed, "arrival at z = -240 mm", PAGE_WAIT_S)  # 150 mm, loaded twin
    for canvas in ("ws-top", "ws-side"):
        wait_for(lambda c=canvas: pixels_of(page, c, REACHABLE_RGB) > 500, f"{canvas} drawn")
    for canvas in ("ws-top", "ws-side"):
        waiting.wait_for(
            lambda c=canvas: colour_at(page, c) == ROBOT_RGB,
            f"the robot's point on {canvas}",
            seen=lambda c=canvas: colour_at(page, c),
        )

    def shown_and_measured() -> tuple[np.ndarray, np.ndarray]:
        text = page.locator("#ws-robot").inner_text().split(" mm")[0]
        shown = np.array([float(v) for v in text.split(",")])
        return shown, 1e3 * np.array(server.get("/api/status")["ee"]["position_m"])

    # the page's readout follows the measured point (read apart: the arm may still settle
    # after the long move, so this waits for the two to agree, not for one read)
    waiting.wait_for(
        lambda: np.allclose(*shown_and_measured(), rtol=0, atol=3.0),
        "the page's robot point to match the measured one within 3 mm",
        seen=shown_and_measured,
    )


def test_a_software_drawn_scene_pauses_while_the_arm_moves(page: Any, server: Server) -> None:
    """Headless chromium draws WebGL in software: the embedded scene's frame is hidden (its
    drawing paused, for the e-stop key's CPU) while the arm moves, with a note saying why,
    and shown again once the arm rests."""
    page.check("#scene-embed", timeout=PAGE_WAIT_S * 1e3)
    frame, note = page.locator("#scene"), page.locator("#scene-paused")
    torque_on(page, server)
    paused = lambda: "paused" in (frame.get_attribute("class") or "")  # noqa: E731
    status = server.get("/api/status")
    z = -0.24 if abs(status["ee"]["position_m"][2] + 0.27) < 0.01 else -0.27  # 30 mm away
    for axis, value in zip("xyz", ("0", "0", f"{z * 1e3:.0f}"), strict=True):
        page.fill(f"#goal-form input[name={axis}]", value)
    page.click("#goal-form button[type=submit]")

    def paused_or_confirmed() -> bool:  # from the hanging arm it is a long move: confirm it
        if page.locator("#confirm").is_visible():
            page.click("#confirm-yes")
        return paused()

    wait_for(paused_or_confirmed, "the scene paused while the arm moves", PAGE_WAIT_S)
    assert note.is_visible() and "paused while the arm moves" in note.inner_text()
    assert frame.evaluate("e => getComputedStyle(e).visibility") == "hidden"
    wait_for(
        lambda: abs(server.get("/api/status")["ee"]["position_m"][2] - z) < 0.002,
        "the arm at the goal",
        PAGE_WAIT_S,
    )
    wait_for(lambda: not paused(), "the scene drawing again once the arm rests", PAGE_WAIT_S)
    assert not note.is_visible()
    page.uncheck("#scene-embed")

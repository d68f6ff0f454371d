"""The servo panel in Debian's chromium against `deltadash serve` on the simulator, walked
as an operator tuning one servo would: choose servo 2 and see its gains read from the
servo, type bad gains and a bad step and have them refused in the page's words with nothing
sent, write gains (the server then holds them, the panel shows them read back), revert, run
a step whose response is drawn on the canvas with its figures, and see the server's refusal
of a step of the relaxed arm in words.
What was sent is read from the requests the page made; a request that must not be sent is
checked by making a harmless one after it and waiting for that."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlparse

import numpy as np
import pytest

from tests.support import wait as waiting
from tests.support.browser import (
    PAGE_WAIT_S,
    browser_skip_reason,
    dashboard_page,
    save_artifact,
    toasts,
)
from tests.support.server import Server, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
FACTORY = {"p": 800, "i": 0, "d": 0, "ff1": 0, "ff2": 0}
MEASURED_RGB = (0xD9, 0x48, 0x0F)  # servopanel.js COLOURS.measured


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    def listen(page: Any) -> None:
        page.sent = []  # (method, path, body) of every request the page made to the panel's routes
        page.on("request", lambda r: record(page, r))

    with dashboard_page(server, on_page=listen) as page:
        yield page


def record(page: Any, request: Any) -> None:
    path = urlparse(request.url).path
    if path.startswith(("/api/servos/", "/api/tuning/")):
        body = json.loads(request.post_data) if request.post_data else None
        page.sent.append((request.method, path, body))


def sent(page: Any, method: str, path: str) -> list[Any]:
    """The bodies of the requests ``method path`` the page made so far (Playwright delivers
    the page's events only during a call into it: one is made first)."""
    page.evaluate("0")
    return [body for m, p, body in page.sent if m == method and p == path]


def text(page: Any, selector: str) -> str:
    return page.locator(selector).inner_text()


def measured_pixels(page: Any) -> int:
    return page.evaluate(
        """(rgb) => {
          const c = document.getElementById("sp-plot");
          const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
          let n = 0;
          for (let k = 0; k < d.length; k += 4) {
            if (d[k] === rgb[0] && d[k + 1] === rgb[1] && d[k + 2] === rgb[2]) n += 1;
          }
          return n;
        }""",
        list(MEASURED_RGB),
    )


def at_rest_home(page: Any, server: Server) -> None:
    """Torque on and the arm at the home point, at rest there, by the page's own buttons."""
    clicked = [-1e9]

    def on() -> bool:
        if server.get("/api/status")["torque"]:
            return True
        if time.monotonic() - clicked[0] > 2.0:  # the twin's arm may still swing at start
            clicked[0] = time.monotonic()
            page.click("#torque-on")
        return False

    waiting.wait_for(on, "torque on", PAGE_WAIT_S, poll_s=0.2, seen=server.brief)
    for axis, value in zip("xyz", ("0", "0", "-240"), strict=True):
        page.fill(f"#goal-form input[name={axis}]", value)
    page.click("#goal-form button[type=submit]")

    def arrived() -> bool:  # from the hanging arm it is a long move: confirm it
        if page.locator("#confirm").is_visible():
            page.click("#confirm-yes")
        return resting(server)

    waiting.wait_for(arrived, "the arm at rest at the home point", PAGE_WAIT_S, seen=server.brief)


def resting(server: Server) -> bool:
    """The arm rests at the home point: its goal's jog stands there and every joint is
    still (a step starts only from rest: after a change of gains the arm sags anew)."""
    status = server.get("/api/status")
    goal, commanded = status["goal"]["position_m"], status["ee"]["commanded_m"]
    if goal is None or abs(commanded[2] + 0.24) > 1e-9:
        return False
    still = all(abs(v or 0.0) < 0.02 for v in status["joints"]["velocity_rad_s"])
    return still and bool(np.allclose(goal, commanded, atol=1e-9))


def test_the_servo_panel_reads_refuses_writes_reverts_and_steps(page: Any, server: Server) -> None:
    at_rest_home(page, server)
    page.locator("#sp-h").scroll_into_view_if_needed()

    # choose servo 2: its gains read from the servo, the registers' limits beside them
    page.select_option("#sp-servo", "2")
    wait_for(lambda: "servo 2: read" in text(page, "#sp-message"), "servo 2's gains read")
    assert sent(page, "GET", "/api/servos/2/gains")
    for name, value in FACTORY.items():
        assert text(page, f"#sp-servo-{name}") == str(value)
        assert page.input_value(f"#sp-gains input[name={name}]") == str(value)
        assert text(page, f"#sp-range-{name}") == "0–16383"
    assert page.locator("#sp-revert").is_disabled()  # nothing to revert yet

    # bad gains: refused in the page's words, the field marked, nothing sent
    refusals = {
        "12,5": 'Not written: P gain: "12,5" is not a whole number (the register takes 0 to 16383)',
        "20000": "Not written: P gain: 20000 is outside 0 to 16383 (the register takes 0 to 16383)",
        "": "Not written: P gain: is empty (the register takes 0 to 16383)",
    }
    for typed, words in refusals.items():
        page.fill("#sp-gains input[name=p]", typed)
        page.click("#sp-write")
        wait_for(lambda w=words: text(page, "#sp-message") == w, f"the refusal of {typed!r}")
        assert page.get_attribute("#sp-gains input[name=p]", "aria-invalid") == "true"
    assert words in toasts(page)
    reads = len(sent(page, "GET", "/api/servos/2/gains"))
    page.click("#sp-read")  # a harmless request after the refused ones
    wait_for(lambda: len(sent(page, "GET", "/api/servos/2/gains")) > reads, "the read's request")
    assert sent(page, "POST", "/api/servos/2/gains") == []
    assert server.get("/api/status")["gains"]["2"] == FACTORY

    # write: the server and the servo hold them, the panel shows them read back
    wait_for(lambda: page.input_value("#sp-gains input[name=p]") == "800", "the read's values")
    page.fill("#sp-gains input[name=p]", "1500")
    page.fill("#sp-gains input[name=d]", "40")
    page.click("#sp-write")
    tuned = {**FACTORY, "p": 1500, "d": 40}
    wait_for(
        lambda: server.get("/api/status")["gains"]["2"] == tuned,
        "servo 2's gains in use on the server",
    )
    wait_for(lambda: text(page, "#sp-servo-p") == "1500", "the written gains read back")
    assert sent(page, "POST", "/api/servos/2/gains") == [tuned]
    assert text(page, "#sp-servo-d") == "40" and "written and read back" in text(
        page, "#sp-message"
    )
    assert server.get("/api/status")["gains"]["1"] == FACTORY  # the other legs keep theirs
    wait_for(lambda: page.locator("#sp-revert").is_enabled(), "Revert to be offered")

    # revert: the factory gains back on the servo, and in the panel
    page.click("#sp-revert")
    wait_for(lambda: server.get("/api/status")["gains"]["2"] == FACTORY, "the revert on the server")
    wait_for(lambda: text(page, "#sp-servo-p") == "800", "the reverted gains read back")
    assert ("POST", "/api/tuning/revert", None) in page.sent

    # a step too large: refused in the page's words, nothing sent
    page.fill("#sp-step-size", "7")
    page.click("#sp-step-run")
    words = "Not stepped: step: 7° is outside 0.5 to 5° either way"
    wait_for(lambda: text(page, "#sp-message") == words, "the refusal of a 7° step")
    runs_before = len(server.get("/api/runs"))

    # a 3° step of joint 2 once the arm rests again (the revert let it sag anew), drawn with
    # its figures
    wait_for(lambda: resting(server), "the arm at rest after the revert", seen=server.brief)
    page.fill("#sp-step-size", "3")
    page.click("#sp-step-run")
    wait_for(
        lambda: page.evaluate("document.getElementById('sp-plot').dataset.drawn || ''"),
        "the step drawn",
        PAGE_WAIT_S,
        seen=lambda: (text(page, "#sp-message"), toasts(page), server.brief()),
    )
    steps = sent(page, "POST", "/api/servos/2/step")
    assert steps == [{"step_rad": pytest.approx(math.radians(3.0))}]  # the 7° one never left
    answer = page.evaluate("window.deltadash.servoPanel.lastStep")
    assert answer["state"] == "done", answer["reason"]
    goal, measured = np.degrees(answer["goal_rad"]), np.degrees(answer["measured_rad"])
    t = np.array(answer["t_s"])
    assert goal[-1] - goal[t < 0][-1] == pytest.approx(3.0, abs=1e-6)
    assert measured[-10:].mean() - measured[t < 0].mean() > 2.4  # it rose towards the goal
    assert abs(measured[-10:].mean() - goal[-1]) < 0.5
    assert measured_pixels(page) > 100  # the measured line is on the canvas
    figures = answer["figures"]
    assert text(page, "#sp-rise") == f"{figures['rise_time_s'] * 1000:.1f} ms"
    assert text(page, "#sp-overshoot") == f"{figures['overshoot_pct']:.1f} %"
    assert f"run {answer['run_id']}" in text(page, "#sp-message")
    runs = server.get("/api/runs")
    assert len(runs) == runs_before + 1
    assert runs[0]["run_id"] == answer["run_id"] and runs[0]["kind"] == "joint-step"
    save_artifact("servo-panel.png", page.screenshot(full_page=True))

    # the server's refusal in the operator's words: no step of a relaxed arm
    page.click("#torque-off")
    wait_for(lambda: not server.get("/api/status")["torque"], "torque off", seen=server.brief)
    page.click("#sp-step-run")
    words = "Torque is off: press Torque on first."
    wait_for(lambda: text(page, "#sp-message") == words, "the server's refusal, in words")
    assert len(sent(page, "POST", "/api/servos/2/step")) == 2  # sent, and refused
    assert len(server.get("/api/runs")) == runs_before + 1  # no run

"""The wrist's servo on the page, against `deltadash serve` on the twin with ``[wrist]
enabled`` (servo 4): its row in the Servos table with the readings the status gives, and
the Servo panel reading and writing its gains and stepping φ, the step drawn with its
record. What was sent is read from the requests the page made."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlparse

import numpy as np
import pytest

from tests.static.test_servo_panel import at_rest_home
from tests.support import wait as waiting
from tests.support.browser import (
    PAGE_WAIT_S,
    PATIENT_SIM_ENV,
    browser_skip_reason,
    dashboard_page,
    save_artifact,
    toasts,
)
from tests.support.server import Server, serve, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
WRIST_ENV = {**PATIENT_SIM_ENV, "DELTADASH_WRIST__ENABLED": "true"}  # servo 4, +-3 rad
FACTORY = {"p": 800, "i": 0, "d": 0, "ff1": 0, "ff2": 0}


@pytest.fixture(scope="module")
def wristed(tmp_path_factory) -> Iterator[Server]:
    with serve(tmp_path_factory.mktemp("wristed"), **WRIST_ENV) as served:
        yield served


@pytest.fixture(scope="module")
def page(wristed: Server) -> Iterator[Any]:
    def listen(page: Any) -> None:
        page.sent = []  # (method, path, body) of the servo panel's requests

        def record(request: Any) -> None:
            path = urlparse(request.url).path
            if path.startswith("/api/servos/"):
                body = json.loads(request.post_data) if request.post_data else None
                page.sent.append((request.method, path, body))

        page.on("request", record)

    with dashboard_page(wristed, stub_scene=False, on_page=listen) as page:
        yield page


def sent(page: Any, method: str, path: str) -> list[Any]:
    page.evaluate("0")  # Playwright delivers the page's events during a call into it
    return [body for m, p, body in page.sent if m == method and p == path]


def text(page: Any, selector: str) -> str:
    return page.locator(selector).inner_text()


def test_servo_4_is_in_the_servos_table_with_its_readings(page: Any, wristed: Server) -> None:
    status = wristed.get("/api/status")
    assert [s["role"] for s in status["servos"]] == ["leg", "leg", "leg", "wrist"]
    assert status["joints"]["servo_ids"] == [1, 2, 3]
    rows = page.locator("#servo-rows tr")
    wait_for(lambda: rows.count() == 4, "four servo rows", PAGE_WAIT_S)
    row = rows.nth(3)
    assert row.locator("th").inner_text() == "4 wrist"
    cells = row.locator("td").all_inner_texts()
    # angle, cmd, vel, current, PWM, V, degC, errors: the status's figures as the legs' are
    wrist = wristed.get("/api/status")["wrist_servo"]
    assert cells[5] == f"{wrist['voltage_v']:.1f}" and cells[6] == f"{wrist['temperature_c']:.0f}"
    assert cells[7] == "none"

    def angle_shown() -> bool:  # phi as read, in degrees, as the status says it
        shown = row.locator("td").first.inner_text()
        phi = wristed.get("/api/status")["wrist_servo"]["position_rad"]
        return shown != "–" and abs(float(shown) - math.degrees(phi)) < 0.2

    wait_for(angle_shown, "the wrist's angle in degrees", PAGE_WAIT_S)
    table = page.locator("section.servos table")
    table.evaluate("el => el.scrollIntoView({ block: 'center' })")  # clear of the header
    save_artifact("wrist-servo-table.png", table.screenshot())


def test_the_servo_panel_reads_writes_and_steps_the_wrist(page: Any, wristed: Server) -> None:
    at_rest_home(page, wristed)
    page.locator("#sp-h").scroll_into_view_if_needed()
    wait_for(lambda: page.locator("#sp-servo option[value='4']").count() == 1, "servo 4 offered")
    assert page.locator("#sp-servo option[value='4']").inner_text() == "servo 4 (wrist, φ)"
    page.select_option("#sp-servo", "4")
    wait_for(lambda: "servo 4: read" in text(page, "#sp-message"), "servo 4's gains read")
    assert sent(page, "GET", "/api/servos/4/gains")
    assert text(page, "#sp-legend-what") == "φ, the wrist's angle"
    assert "φ within -171.9 to 171.9°" in text(page, "#sp-step-range")
    assert page.locator("#sp-revert").is_disabled()  # the revert is the legs'

    # write: the wrist's servo holds them (read back from it), the legs keep theirs
    page.fill("#sp-gains input[name=p]", "1200")
    page.click("#sp-write")
    wait_for(lambda: text(page, "#sp-servo-p") == "1200", "the written P read back", PAGE_WAIT_S)
    assert sent(page, "POST", "/api/servos/4/gains") == [{**FACTORY, "p": 1200}]
    assert all(wristed.get("/api/status")["gains"][str(k)] == FACTORY for k in (1, 2, 3))

    # a 3 degree step of phi, the legs held: drawn with its record
    waiting.wait_for(
        lambda: wristed.get("/api/status")["mode"] in ("idle", "jog"),
        "the arm at rest",
        PAGE_WAIT_S,
        seen=wristed.brief,
    )
    page.fill("#sp-step-size", "3")
    page.click("#sp-step-run")
    wait_for(
        lambda: page.evaluate("document.getElementById('sp-plot').dataset.drawn || ''"),
        "the step drawn",
        PAGE_WAIT_S,
        seen=lambda: (text(page, "#sp-message"), toasts(page), wristed.brief()),
    )
    assert sent(page, "POST", "/api/servos/4/step") == [
        {"step_rad": pytest.approx(math.radians(3.0))}
    ]
    answer = page.evaluate("window.deltadash.servoPanel.lastStep")
    assert answer["state"] == "done", answer["reason"]
    assert answer["joint"] == 4
    goal, measured = np.degrees(answer["goal_rad"]), np.degrees(answer["measured_rad"])
    t = np.array(answer["t_s"])
    assert goal[-1] - goal[t < 0][-1] == pytest.approx(3.0, abs=1e-6)
    assert measured[-10:].mean() - measured[t < 0].mean() > 2.4  # it turned towards the goal
    panel = page.locator("section.servo-panel")
    panel.evaluate("el => el.scrollIntoView({ block: 'center' })")
    save_artifact("wrist-servo-panel.png", panel.screenshot())

    page.fill("#sp-gains input[name=p]", "800")  # the factory's back
    page.click("#sp-write")
    wait_for(lambda: text(page, "#sp-servo-p") == "800", "the factory P back", PAGE_WAIT_S)

"""The operator's view of the tool and the wrist, against `deltadash serve` on the twin with
``[tool] offset_m`` and ``[wrist] enabled``: the wrist angle and the tool offset shown, a
Go-to with a typed phi (a decimal comma) turning the wrist there, a phi jog key and the pad's
+phi button stepping it, the phi plot drawn, the 2D view marking the platform centre beside
the tip. Without a wrist none of the wrist's controls appear. Every wait is on a condition
(the server's status, the page's state), never a fixed sleep.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterator
from typing import Any
from urllib.parse import parse_qsl, urlsplit

import pytest

from tests.support.browser import (
    PATIENT_SIM_ENV,
    browser_skip_reason,
    dashboard_page,
    page_condition,
    plots_frame,
    toasts,
)
from tests.support.server import Server, serve, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
OFFSET_M = [0.0, 0.0, -0.04]
TOOL_ENV = {
    **PATIENT_SIM_ENV,
    "DELTADASH_TOOL__OFFSET_M": json.dumps(OFFSET_M),
    "DELTADASH_WRIST__ENABLED": "true",
}
STEP_RAD = math.radians(5)  # wrist.js PHI_STEP_DEG
PHI_TOL_RAD = 0.01
DEGREE = math.radians(0.5) + 1e-6  # the 2D view cuts its sections at whole degrees


@pytest.fixture(scope="module")
def tooled(tmp_path_factory) -> Iterator[Server]:
    with serve(tmp_path_factory.mktemp("tooled"), **TOOL_ENV) as served:
        yield served


@pytest.fixture(scope="module")
def page(tooled: Server) -> Iterator[Any]:
    def listen(page: Any) -> None:
        page.goals = []  # every POST /api/goal body the page sent, in order
        page.workspace = []  # every GET /api/workspace/... query the page sent, parsed
        page.on("request", lambda r: record_goal(page, r))

    with dashboard_page(tooled, stub_scene=False, on_page=listen) as page:
        yield page


def record_goal(page: Any, request: Any) -> None:
    if request.method == "POST" and request.url.endswith("/api/goal"):
        page.goals.append(json.loads(request.post_data))
    url = urlsplit(request.url)
    if url.path.startswith("/api/workspace/"):
        page.workspace.append((url.path, dict(parse_qsl(url.query))))


def status(server: Server) -> dict:
    return server.get("/api/status")


def text(page: Any, selector: str) -> str:
    return page.locator(selector).inner_text()


def seen(page: Any, server: Server):
    return lambda: {**server.brief(), "messages": toasts(page), "goal": status(server)["goal"]}


def torque_on(page: Any, server: Server) -> None:
    click = "sel => document.querySelector(sel).click()"
    wait_for(
        lambda: status(server)["torque"] or page.evaluate(click, "#torque-on"),
        "torque on",
        seen=server.brief,
    )


def phi_at(server: Server, phi_rad: float) -> bool:
    s = status(server)
    return s["mode"] != "fault" and abs(s["ee"]["phi_rad"] - phi_rad) < PHI_TOL_RAD


def test_the_wrist_angle_the_tool_and_the_phi_plot_are_shown(page: Any, tooled: Server) -> None:
    info = tooled.get("/api/info")
    assert info["wrist"]["enabled"] and info["tool_offset_m"] == OFFSET_M
    wait_for(lambda: page.locator("#phi-meas").is_visible(), "the wrist angle shown")
    wait_for(lambda: re.fullmatch(r"-?\d+\.\d°", text(page, "#phi-meas")), "phi in degrees")
    assert text(page, "#tool-offset") == "(0.0, 0.0, -40.0) mm at φ = 0"
    assert page.locator("#goal-form input[name=phi]").is_enabled()
    assert page.locator("[data-phi='1']").is_visible()
    plots = plots_frame(page)
    page_condition(
        plots, "window.deltadashPhiPlot && window.deltadashPhiPlot.frames > 0", "phi plot"
    )
    assert plots.locator("#plot-phi .scatterlayer .trace").count() == 2  # goal and measured
    # the 2D view: the platform centre marked beside the tip, 40 mm above it in the side view
    page_condition(page, "document.getElementById('ws-side').dataset.platformPx", "the platform")
    side = page.locator("#ws-side")
    platform = [int(v) for v in side.get_attribute("data-platform-px").split(",")]
    tip = [int(v) for v in side.get_attribute("data-robot-px").split(",")]
    assert platform[1] < tip[1]  # canvas y grows downwards: the platform is above the tip


def test_go_to_with_a_typed_phi_turns_the_wrist_there(page: Any, tooled: Server) -> None:
    torque_on(page, tooled)
    for name, value in (("x", "0"), ("y", "0"), ("z", "-270,00"), ("phi", "20,5")):
        page.fill(f"#goal-form input[name={name}]", value)
    sent = len(page.goals)
    page.click("#goal-form button[type=submit]")
    want = math.radians(20.5)

    def arrived() -> bool:  # from where torque on holds it, a long move is confirmed first
        if page.locator("#confirm").is_visible():
            page.click("#confirm-yes")
        elif status(tooled)["mode"] == "fault":  # a starved twin: as an operator would
            page.click("#reset")
            wait_for(lambda: status(tooled)["mode"] != "fault", "the fault reset")
            torque_on(page, tooled)
            page.click("#goal-form button[type=submit]")
            return False
        return phi_at(tooled, want)

    wait_for(arrived, "the wrist at the typed 20.5°", seen=seen(page, tooled))
    page.evaluate("0")  # Playwright delivers the recorded requests during a call into the page
    body = page.goals[sent]
    assert body["position_m"] == pytest.approx([0.0, 0.0, -0.27], abs=1e-12)
    assert body["phi_rad"] == pytest.approx(want, abs=1e-12)
    assert status(tooled)["goal"]["phi_rad"] == pytest.approx(want, abs=1e-12)
    wait_for(lambda: text(page, "#phi-goal") == "20.5°", "the page showing the goal's phi")
    # the 2D view checked the typed tip at its own angle, and cuts at the goal's angle now
    # (to a degree): the tips' region turns with the wrist
    asked = lambda path: [float(q.get("phi_rad", "nan")) for p, q in page.workspace if p == path]  # noqa: E731
    assert any(abs(phi - want) < 1e-5 for phi in asked("/api/workspace/nearest")), page.workspace
    wait_for(
        lambda: (
            page.evaluate("0") == 0
            and any(abs(phi - want) <= DEGREE for phi in asked("/api/workspace/section"))
        ),
        "a section cut at the goal's angle",
        seen=lambda: page.workspace[-4:],
    )


def step_and_wait(page: Any, server: Server, press: Any, sign: int, what: str) -> None:
    before = status(server)["goal"]["phi_rad"]
    assert before is not None
    want = before + sign * STEP_RAD
    press()
    wait_for(
        lambda: abs(status(server)["goal"]["phi_rad"] - want) < 1e-9,
        f"{what}: the wrist's goal one step on",
        seen=seen(page, server),
    )
    wait_for(lambda: phi_at(server, want), f"{what}: the wrist there", seen=seen(page, server))


def test_a_phi_key_and_the_pad_step_the_wrist(page: Any, tooled: Server) -> None:
    torque_on(page, tooled)
    wait_for(lambda: status(tooled)["goal"]["phi_rad"] is not None, "a wrist goal held")
    page.check("#jog-keys")
    page.locator("#jog-h").click()  # focus out of the form: keys typed there never jog
    step_and_wait(page, tooled, lambda: page.keyboard.press("e"), 1, "the E key")
    step_and_wait(page, tooled, lambda: page.keyboard.press("["), -1, "the [ key")
    page.uncheck("#jog-keys")
    step_and_wait(page, tooled, lambda: page.click("[data-phi='1']"), 1, "the +φ pad button")


def test_without_a_wrist_no_phi_control_appears(page: Any, tooled: Server, tmp_path) -> None:
    """The same browser page, on a server without [tool] and [wrist] (one Playwright per
    process: the module's page goes there and back)."""
    with serve(tmp_path, **PATIENT_SIM_ENV) as plain:
        try:
            page.goto(plain.url + "/", wait_until="commit")
            wait_for(lambda: text(page, "#pos-meas") != "–", "the page showing the robot")
            page_condition(page, "document.getElementById('ws-side').dataset.robotPx", "robot")
            for selector in ("[data-wrist]", "[data-tool]"):
                shown = page.locator(selector).evaluate_all("els => els.filter(e => !e.hidden)")
                assert shown == [], selector
            assert page.locator("#goal-form input[name=phi]").is_disabled()
            plots = plots_frame(page)
            wait_for(lambda: plots.evaluate("window.deltadashPlot.connected"), "the plots")
            assert not plots.locator("#plot-phi").is_visible()
            assert plots.evaluate("window.deltadashPhiPlot.frames") == 0
            assert page.locator("#ws-side").get_attribute("data-platform-px") is None
        finally:
            page.goto(tooled.url + "/", wait_until="commit")

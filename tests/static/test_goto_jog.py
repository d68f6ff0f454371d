"""Issue 32, Go-to and jog, against `deltadash serve` on the twin with a wrist and a tool:

- a goal that turns the wrist more than the page's setting (30 deg) asks first, and a second
  tab shows the wrist's current angle in its Go-to field (and its turn in the preview);
- the preview follows the arm without typing;
- a target the gate refuses offers the nearest point it accepts BEFORE any "Move?", the
  point GET /api/workspace/nearest gives (the CLI's, tests/app/server/test_nearest.py);
- a step jog moves the commanded point by exactly its step, through POST /api/jog;
- notices in their own neutral strip, not the red fault strip; the take-control question
  in the page's words;
- the 2D view's scale bar against the tool's known 40 mm; the header's backend not cut;
- over a slow link (the page's status requests held back by Playwright routing) the header
  says "link slow: ... ms".

Every wait is on a condition with a deadline; what was sent is read from the page's requests.
"""

from __future__ import annotations

import json
import math
import re
import time
from collections.abc import Iterator
from typing import Any
from urllib.parse import parse_qsl, urlsplit

import pytest

from tests.support.browser import (
    PAGE_WAIT_S,
    PATIENT_SIM_ENV,
    browser_skip_reason,
    dashboard_page,
    page_condition,
    save_artifact,
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
PHI_TOL_RAD = 0.01
TRIPLE_MM = re.compile(r"\((-?\d+\.\d+), (-?\d+\.\d+), (-?\d+\.\d+)\) mm")


@pytest.fixture(scope="module")
def tooled(tmp_path_factory) -> Iterator[Server]:
    with serve(tmp_path_factory.mktemp("goto"), **TOOL_ENV) as served:
        yield served


def listen(page: Any) -> None:
    page.sent = []  # every POST /api/goal and /api/jog: (path, body), in order
    page.on("request", lambda r: record(page, r))


def record(page: Any, request: Any) -> None:
    path = urlsplit(request.url).path
    if request.method == "POST" and path in ("/api/goal", "/api/jog"):
        page.sent.append((path, json.loads(request.post_data)))
    if path == "/api/workspace/nearest":
        page.sent.append((path, dict(parse_qsl(urlsplit(request.url).query))))


@pytest.fixture(scope="module")
def page(tooled: Server) -> Iterator[Any]:
    with dashboard_page(tooled, on_page=listen) as page:
        yield page


def status(server: Server) -> dict:
    return server.get("/api/status")


def text(page: Any, selector: str) -> str:
    return page.locator(selector).inner_text()


def visible(page: Any, selector: str) -> bool:
    return page.locator(selector).is_visible()


def sent(page: Any, path: str) -> list[dict]:
    page.evaluate("0")  # Playwright delivers recorded requests during a call into the page
    return [body for p, body in page.sent if p == path]


def seen(page: Any, server: Server):
    return lambda: {**server.brief(), "messages": toasts(page), "goal": status(server)["goal"]}


def torque_on(page: Any, server: Server) -> None:
    click = "sel => document.querySelector(sel).click()"
    wait_for(
        lambda: status(server)["torque"] or page.evaluate(click, "#torque-on"),
        "torque on",
        seen=server.brief,
    )


def fill(page: Any, **values: str) -> None:
    for name, value in values.items():
        page.fill(f"#goal-form input[name={name}]", value)


def at_rest(server: Server, point_m: list[float], phi_rad: float | None = None) -> bool:
    s = status(server)
    there = s["ee"]["commanded_m"] == pytest.approx(point_m, abs=1e-6)
    close = all(abs(a - b) < 0.002 for a, b in zip(s["ee"]["position_m"], point_m, strict=True))
    turned = phi_rad is None or abs(s["ee"]["phi_rad"] - phi_rad) < PHI_TOL_RAD
    return s["mode"] != "fault" and there and close and turned


def preview_distance(page: Any) -> float:
    return float(re.search(r"distance (\d+\.\d\d) mm", text(page, "#goal-preview")).group(1))


def submit_confirmed(page: Any, server: Server, point_m: list[float], phi_rad: float) -> None:
    """Go, confirming what is asked, until the arm rests there (a starved twin's fault is
    reset and the goal sent again, as an operator would)."""
    page.click("#goal-form button[type=submit]")

    def arrived() -> bool:
        if visible(page, "#confirm"):
            page.click("#confirm-yes")
        elif status(server)["mode"] == "fault":
            page.click("#reset")
            wait_for(lambda: status(server)["mode"] != "fault", "the fault reset")
            torque_on(page, server)
            page.click("#goal-form button[type=submit]")
            return False
        return at_rest(server, point_m, phi_rad)

    wait_for(arrived, "the arm at the goal", seen=seen(page, server))


def test_a_large_wrist_turn_asks_and_a_second_tab_shows_the_current_phi(
    page: Any, tooled: Server
) -> None:
    """Issue 32 point 2: tab A turns the wrist to 60 deg (asked: over 30 deg); tab B opens
    with 60.0 in its phi field and a preview turning nothing; typing 0 there shows a 60 deg
    turn, and Go asks before sending (cancel: nothing sent, the wrist stays)."""
    torque_on(page, tooled)
    home = tooled.get("/api/info")["home_m"]
    z = f"{home[2] * 1000:.2f}"
    fill(page, x="0", y="0", z=z, phi="60")
    wait_for(lambda: "wrist turn 60.0°" in text(page, "#goal-preview"), "the turn in the preview")
    before = len(sent(page, "/api/goal"))
    page.click("#goal-form button[type=submit]")
    wait_for(lambda: visible(page, "#confirm"), "the wrist-turn question", seen=seen(page, tooled))
    asked = text(page, "#confirm-text")
    assert "turns the wrist 60.0°, more than 30°" in asked, asked
    assert len(sent(page, "/api/goal")) == before  # asked before anything was sent
    page.click("#confirm-yes")
    wait_for(lambda: len(sent(page, "/api/goal")) > before, "the goal request")
    want = math.radians(60)
    assert sent(page, "/api/goal")[before]["phi_rad"] == pytest.approx(want, abs=1e-12)
    submit_confirmed(page, tooled, [0.0, 0.0, home[2]], want)

    second = page.context.new_page()
    second.sent = []
    second.on("request", lambda r: record(second, r))
    try:
        second.goto(tooled.url + "/", wait_until="commit", timeout=PAGE_WAIT_S * 1e3)
        phi_field = second.locator("#goal-form input[name=phi]")
        wait_for(
            lambda: phi_field.input_value() == "60.0",
            "tab B's phi field at 60.0",
            seen=lambda: phi_field.input_value(),
        )
        wait_for(lambda: "wrist turn 0.0°" in text(second, "#goal-preview"), "no turn in B")
        assert preview_distance(second) < 0.01
        save_artifact("goto-second-tab.png", second.screenshot(full_page=False))
        phi_field.fill("0")
        wait_for(lambda: "wrist turn 60.0°" in text(second, "#goal-preview"), "B's turn shown")
        second.click("#goal-form button[type=submit]")
        wait_for(lambda: visible(second, "#confirm"), "tab B asks before turning the wrist")
        asked = text(second, "#confirm-text")
        assert "turns the wrist 60.0°" in asked and "Move?" in asked, asked
        second.click("#confirm-no")
        wait_for(lambda: "nothing was sent" in text(second, "#toast"), "the cancel said")
        assert sent(second, "/api/goal") == []
        assert status(tooled)["goal"]["phi_rad"] == pytest.approx(want, abs=1e-9)
    finally:
        second.close()


def test_the_preview_follows_the_arm_without_typing(page: Any, tooled: Server) -> None:
    """Issue 32 point 6: the preview's distance updates as the arm moves (a step jog here),
    not only when typing; the fields, once typed, stay the operator's."""
    torque_on(page, tooled)
    goal = status(tooled)["goal"]["position_m"]
    target = [round(goal[0] * 1000 + 20, 2), round(goal[1] * 1000, 2), round(goal[2] * 1000, 2)]
    fill(page, x=f"{target[0]:.2f}", y=f"{target[1]:.2f}", z=f"{target[2]:.2f}")
    wait_for(lambda: abs(preview_distance(page) - 20.0) < 0.011, "a 20 mm preview")
    page.select_option("#jog-step", "10")
    page.click("[data-jog='x+']")  # 10 mm towards the target: the preview says 10 mm left
    wait_for(
        lambda: abs(preview_distance(page) - 10.0) < 0.011,
        "the preview after the step",
        seen=lambda: text(page, "#goal-preview"),
    )
    assert page.locator("#goal-form input[name=x]").input_value() == f"{target[0]:.2f}"
    page.select_option("#jog-step", "hold")


def test_a_step_jog_moves_exactly_its_step(page: Any, tooled: Server) -> None:
    """Issue 32: a step jog (0.1 / 1 / 10 mm) beside hold-to-jog: one press, one
    POST /api/jog with delta_m, and the loop's commanded point moves by exactly the step."""
    torque_on(page, tooled)
    for step_mm, button, axis, sign in (
        ("10", "y-", 1, -1),
        ("1", "z+", 2, 1),
        ("0.1", "x-", 0, -1),
    ):
        page.select_option("#jog-step", step_mm)
        # the arm may still be on its way to the goal a step before left: start from rest
        start = wait_for(
            lambda: (g := status(tooled)["goal"]["position_m"]) and at_rest(tooled, g) and g,
            "the arm at rest before the step",
            seen=seen(page, tooled),
        )
        jogs = len(sent(page, "/api/jog"))
        page.click(f"[data-jog='{button}']")
        want = list(start)
        want[axis] += sign * float(step_mm) / 1000
        wait_for(
            lambda w=want: at_rest(tooled, w), f"the step of {step_mm} mm", seen=seen(page, tooled)
        )
        moved = [a - b for a, b in zip(status(tooled)["ee"]["commanded_m"], start, strict=True)]
        assert math.hypot(*moved) == pytest.approx(float(step_mm) / 1000, abs=1e-9)
        bodies = sent(page, "/api/jog")[jogs:]
        delta = [0.0, 0.0, 0.0]
        delta[axis] = sign * float(step_mm) / 1000
        assert bodies == [{"delta_m": pytest.approx(delta, abs=1e-15)}], bodies  # no hold
    page.select_option("#jog-step", "hold")


def test_an_outside_target_offers_the_nearest_point_before_any_move_question(
    page: Any, tooled: Server
) -> None:
    """Issue 32 point 6: (250, 0, -240) mm is refused by the gate: the page offers the
    nearest point it accepts (GET /api/workspace/nearest's, the CLI's) before "Move?", and
    sends exactly it; nothing goes before the answer."""
    torque_on(page, tooled)
    phi = status(tooled)["goal"]["phi_rad"]
    fill(page, x="250", y="0", z="-240", phi=f"{math.degrees(phi):.1f}")
    goals = len(sent(page, "/api/goal"))
    page.click("#goal-form button[type=submit]")
    wait_for(lambda: visible(page, "#confirm"), "the nearest-point question")
    asked = text(page, "#confirm-text")
    assert "outside where the arm may go" in asked and "Go there instead?" in asked, asked
    assert "Move?" not in asked
    assert text(page, "#confirm-yes") == "Go to nearest"
    assert len(sent(page, "/api/goal")) == goals
    query = {"x_m": 0.25, "y_m": 0.0, "z_m": -0.24, "phi_rad": round(phi, 6)}
    api = tooled.get("/api/workspace/nearest?" + "&".join(f"{k}={v}" for k, v in query.items()))
    assert api["inside"] is False
    offered = [float(v) for v in TRIPLE_MM.findall(asked)[1]]
    assert offered == pytest.approx([v * 1000 for v in api["nearest_m"]], abs=0.006)
    page.click("#confirm-yes")
    wait_for(lambda: len(sent(page, "/api/goal")) > goals, "the nearest point sent")
    body = sent(page, "/api/goal")[goals]
    assert body["position_m"] == pytest.approx(api["nearest_m"], abs=1e-6)
    wait_for(
        lambda: at_rest(tooled, body["position_m"]),
        "the arm at the nearest point",
        seen=seen(page, tooled),
    )


def test_notices_show_apart_from_faults(page: Any, tooled: Server) -> None:
    """Issue 32 point 7: "starting from the measured position" (the first motion after
    torque on) in the neutral notice strip, never in the red fault strip."""
    torque_on(page, tooled)
    page.click("#torque-off")
    if visible(page, "#confirm"):
        page.click("#confirm-yes")
    wait_for(lambda: not status(tooled)["torque"], "torque off")
    torque_on(page, tooled)
    page.select_option("#jog-step", "1")
    page.click("[data-jog='z+']")
    wait_for(
        lambda: "starting from the measured position" in text(page, "#notices"),
        "the notice",
        seen=lambda: {**status(tooled), "faults": text(page, "#faults")},
    )
    assert visible(page, "#notices")
    assert "starting from" not in page.locator("#faults").text_content()
    colour = page.locator("#notices").evaluate("el => getComputedStyle(el).backgroundColor")
    fault_colour = page.locator("#faults").evaluate("el => getComputedStyle(el).backgroundColor")
    assert colour != fault_colour
    save_artifact(
        "goto-notice.png", page.screenshot(clip={"x": 0, "y": 0, "width": 1366, "height": 160})
    )
    page.select_option("#jog-step", "hold")


def test_the_2d_view_has_a_scale_and_the_backend_is_not_cut(page: Any, tooled: Server) -> None:
    """Issue 32 point 7: the scale bar's pixels per mm are the view's (the tool's 40 mm
    between the platform centre and the tip in the side view); the header's backend fits at
    1366x900 and 1280x800."""
    page_condition(page, "document.getElementById('ws-side').dataset.scalePx", "the scale bar")
    side = page.locator("#ws-side")
    wait_for(lambda: side.get_attribute("data-platform-px") is not None, "the platform drawn")
    scale_mm = float(side.get_attribute("data-scale-mm"))
    scale_px = float(side.get_attribute("data-scale-px"))
    platform = [int(v) for v in side.get_attribute("data-platform-px").split(",")]
    tip = [int(v) for v in side.get_attribute("data-robot-px").split(",")]
    px_per_mm = math.hypot(platform[0] - tip[0], platform[1] - tip[1]) / 40.0
    assert scale_px / scale_mm == pytest.approx(px_per_mm, rel=0.05)
    assert scale_mm in (10, 20, 50, 100, 200)
    save_artifact("goto-workspace-scale.png", page.locator(".workspace2d").screenshot())
    try:
        for width, height in ((1366, 900), (1280, 800)):
            page.set_viewport_size({"width": width, "height": height})
            wait_for(lambda: text(page, "#backend") != "–", "the backend named")
            fits = page.locator("#backend").evaluate("el => el.scrollWidth <= el.clientWidth + 1")
            assert fits, (width, text(page, "#backend"))
            save_artifact(
                f"goto-header-{width}.png",
                page.screenshot(clip={"x": 0, "y": 0, "width": width, "height": 120}),
            )
    finally:
        page.set_viewport_size({"width": 1366, "height": 900})


def test_the_take_control_question_is_in_the_pages_words(page: Any, tooled: Server) -> None:
    tooled.post("/api/lease", {"client": "bench laptop", "take_over": True})
    page.click("#reset")
    wait_for(lambda: visible(page, "#confirm"), "the take-control question")
    asked = text(page, "#confirm-text")
    assert "bench laptop" in asked and "Take control" in text(page, "#confirm-yes")
    for api_word in ("take_over", "lease", "POST", "/api/"):
        assert api_word not in asked, asked
    page.click("#confirm-yes")
    wait_for(
        lambda: (tooled.get("/api/lease")["holder"] or "").startswith("dashboard-"),
        "the page to hold control",
    )


def test_a_slow_link_is_said_in_the_header(page: Any, tooled: Server) -> None:
    """Issue 32: the page's status requests held back 450 ms (Playwright routing, released
    by the test's own polling: no sleep): the header's link fact says "link slow"."""
    held: list[tuple[float, Any]] = []
    hold_s = 0.45

    def delay(route: Any) -> None:
        held.append((time.monotonic(), route))

    def release() -> None:
        page.evaluate("0")  # routes arrive during a call into the page
        now = time.monotonic()
        while held and now - held[0][0] >= hold_s:
            held.pop(0)[1].continue_()

    def said() -> str | None:
        release()
        conn = text(page, "#conn")
        return conn if conn.startswith("link slow: ") else None

    page.route("**/api/status", delay)
    try:
        conn = wait_for(
            said, "the header to say the link is slow", seen=lambda: text(page, "#conn")
        )
        assert int(re.search(r"(\d+) ms", conn).group(1)) >= 300
        save_artifact(
            "goto-link-slow.png",
            page.screenshot(clip={"x": 0, "y": 0, "width": 1366, "height": 80}),
        )
    finally:
        page.unroute("**/api/status")
        for _, route in held:
            route.continue_()
    wait_for(lambda: text(page, "#conn") == "connected", "the link fact back to connected")

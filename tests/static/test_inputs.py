"""The dashboard's inputs cannot surprise, its state is never stale, and it says what to do.

One page against `deltadash serve` on the simulator, walked in order as a new operator would:
the first-steps guidance (torque on, go home, with the long move confirmed), a decimal comma
in Go-to (12,5 is 12.5 mm, never 125), goals to 0.01 mm, a long move asked first (cancel sends
nothing), torque off while moving asked first, the error blank after torque off and the test
preview about where the arm is now, toasts that clear with their condition, stale values
greyed. What was sent is read from the requests the page made, and from the server; a request
that must not be sent is checked by sending a harmless one after it and waiting for that.
"""

from __future__ import annotations

import json
import re
import urllib.error
from collections.abc import Iterator
from typing import Any

import pytest

from tests.support import wait as waiting
from tests.support.browser import (
    browser_skip_reason,
    dashboard_page,
    page_condition,
    toasts,
)
from tests.support.server import Server, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
TRIPLE_MM = re.compile(r"\((-?\d+\.\d+), (-?\d+\.\d+), (-?\d+\.\d+)\) mm")


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    def listen(page: Any) -> None:
        page.goals = []  # every POST /api/goal body the page sent, in order
        page.on("request", lambda r: record_goal(page, r))

    with dashboard_page(server, on_page=listen) as page:
        yield page


def goals_after(page: Any, sent: int) -> bool:
    """Whether the page has sent a goal since ``sent`` were recorded. Playwright delivers a
    page's events (the recorded requests) only during a call into it: make one first."""
    page.evaluate("0")
    return len(page.goals) > sent


def record_goal(page: Any, request: Any) -> None:
    if request.method == "POST" and request.url.endswith("/api/goal"):
        page.goals.append(json.loads(request.post_data)["position_m"])


def status(server: Server) -> dict:
    return server.get("/api/status")


def text(page: Any, selector: str) -> str:
    return page.locator(selector).inner_text()


def visible(page: Any, selector: str) -> bool:
    return page.locator(selector).is_visible()


def torque_on(page: Any, server: Server, button: str = "#torque-on") -> None:
    # clicked until accepted: the relaxed twin's arm may still swing past its joint limits
    # (a click in the page: a button the accepted torque disabled meanwhile ignores it)
    click = "sel => document.querySelector(sel).click()"
    wait_for(
        lambda: status(server)["torque"] or page.evaluate(click, button),
        "torque on",
        seen=server.brief,
    )


def type_goal(page: Any, x: str, y: str, z: str) -> None:
    for name, value in zip("xyz", (x, y, z), strict=True):
        page.fill(f"#goal-form input[name={name}]", value)


def go_and_wait_sent(page: Any, expect_m: list[float]) -> None:
    """Submit the form and wait until the page has sent ``expect_m`` (no confirmation)."""
    sent = len(page.goals)
    page.click("#goal-form button[type=submit]")
    wait_for(lambda: goals_after(page, sent), "the goal request")
    assert page.goals[sent:] == [pytest.approx(expect_m, abs=1e-12)], page.goals[sent:]


def at_rest_near(server: Server, point_m: list[float], tol_m: float = 0.002) -> bool:
    s = status(server)
    close = all(abs(a - b) < tol_m for a, b in zip(s["ee"]["position_m"], point_m, strict=True))
    # a goal's move stays the "jog" source at its target: arrived when the command is there
    there = s["ee"]["commanded_m"] == pytest.approx(point_m, abs=1e-6)
    return close and there and s["mode"] != "fault"


def arrive(page: Any, server: Server, point_m: list[float], what: str) -> None:
    """Wait until the arm is at rest at ``point_m``. A loaded machine can starve the simulator
    into a stale-feedback fault mid-move: then Reset, torque on and send the goal again from
    the form (confirming it when it is long), as an operator would."""

    def step() -> bool:
        try:
            s = status(server)
        except urllib.error.HTTPError as exc:  # the node's link late on a loaded machine
            if exc.code == 503:
                return False
            raise
        if visible(page, "#confirm"):
            page.click("#confirm-yes")
        elif s["mode"] == "fault":
            page.click("#reset")
            wait_for(lambda: status(server)["mode"] != "fault", "the fault reset")
            torque_on(page, server)
            type_goal(page, *(f"{v * 1000:.2f}" for v in point_m))
            page.click("#goal-form button[type=submit]")
            return False
        return at_rest_near(server, point_m)

    def seen() -> dict[str, Any]:
        return {**server.brief(), "messages": toasts(page)}

    waiting.wait_for(step, what, poll_s=0.1, seen=seen)


def test_first_steps_say_torque_on_then_go_home(page: Any, server: Server) -> None:
    info = server.get("/api/info")
    home = info["home_m"]
    wait_for(lambda: visible(page, "#first-steps"), "the first-steps guidance (torque is off)")
    assert not status(server)["torque"]
    why = text(page, "#first-steps-why")
    assert "Torque on, then go to the home point" in why
    assert re.search(r"z = -\d+ mm", why), why  # where it hangs, in mm
    assert page.locator("#first-home").is_disabled()  # step 2 only after step 1
    home_mm = "(" + ", ".join(f"{v * 1000:.2f}" for v in home) + ") mm"
    assert text(page, "#home-point") == home_mm

    torque_on(page, server, "#first-torque")
    wait_for(
        lambda: page.locator("#first-home").is_enabled() or not visible(page, "#first-steps"),
        "the home step offered",
    )
    z_hanging = status(server)["ee"]["position_m"][2]
    assert z_hanging < home[2] - info["confirm_move_m"], "the arm should hang below home"
    sent = len(page.goals)
    page.click("#first-home")
    # a long move: the target and distance are shown, and nothing is sent before Move
    wait_for(lambda: visible(page, "#confirm"), "the long-move confirmation")
    asked = text(page, "#confirm-text")
    assert f"target {home_mm}" in asked, asked
    distance = float(re.search(r"distance (\d+\.\d\d) mm", asked).group(1))
    assert distance > info["confirm_move_m"] * 1000
    assert len(page.goals) == sent
    page.click("#confirm-yes")

    def sent_home() -> bool:  # a click a busy page lost leaves the question open: again
        if goals_after(page, sent):
            return True
        if visible(page, "#confirm"):
            page.click("#confirm-yes")
        return False

    wait_for(
        sent_home,
        "the goal request",
        seen=lambda: {"confirm shown": visible(page, "#confirm"), "messages": toasts(page)},
    )
    assert page.goals[sent] == pytest.approx(home, abs=1e-12)
    arrive(page, server, home, "arrival at the home point")
    wait_for(lambda: not visible(page, "#first-steps"), "the guidance to go once home")


def test_a_decimal_comma_is_a_decimal_point_never_a_tenfold_move(page: Any, server: Server) -> None:
    home = server.get("/api/info")["home_m"]
    z = f"{home[2] * 1000:.2f}"
    type_goal(page, "12,5", "0", z)
    wait_for(lambda: "target (12.50, 0.00," in text(page, "#goal-preview"), "the preview of 12,5")
    go_and_wait_sent(page, [0.0125, 0.0, home[2]])
    wait_for(
        lambda: status(server)["goal"]["position_m"][0] == pytest.approx(0.0125, abs=1e-9),
        "the server's goal x = 12.5 mm",
    )

    # ambiguous text is refused visibly, and not sent: the next good goal is the next request
    type_goal(page, "1,234.5", "0", z)
    wait_for(lambda: "Not sent: x:" in text(page, "#goal-preview"), "the refusal in the preview")
    assert page.locator("#goal-form input[name=x]").get_attribute("aria-invalid") == "true"
    sent = len(page.goals)
    said = len(toasts(page))
    page.click("#goal-form button[type=submit]")
    # read from the page's record of its message line: the live preview's next status may
    # clear the message with its condition before a poll of a loaded page looks at it
    wait_for(
        lambda: any("Not sent" in m for m in toasts(page)[said:]),
        "the refusal in the message line",
        seen=lambda: toasts(page),
    )
    type_goal(page, "10,01", "0", z)
    go_and_wait_sent(page, [0.01001, 0.0, home[2]])
    assert len(page.goals) == sent + 1


def test_goals_are_typed_sent_and_shown_to_a_hundredth_of_a_mm(page: Any, server: Server) -> None:
    home = server.get("/api/info")["home_m"]
    type_goal(page, "10.01", "-0.01", f"{home[2] * 1000:.2f}")
    go_and_wait_sent(page, [0.01001, -0.00001, home[2]])
    goal = [0.01001, -0.00001, home[2]]
    wait_for(
        lambda: status(server)["goal"]["position_m"] == pytest.approx(goal, abs=1e-9),
        "the server's goal to the hundredth of a mm",
        seen=lambda: {**server.brief(), "messages": toasts(page)},
    )
    wait_for(lambda: text(page, "#pos-goal").startswith("10.01, -0.01,"), "the goal shown in mm")


def test_a_long_move_asks_first_and_cancel_sends_nothing(page: Any, server: Server) -> None:
    home = server.get("/api/info")["home_m"]
    arrive(page, server, [0.01001, -0.00001, home[2]], "the arm at rest")
    far_z = home[2] * 1000 - 60  # 60 mm below: over the 50 mm default
    type_goal(page, "10.01", "-0.01", f"{far_z:.2f}")
    sent = len(page.goals)
    page.click("#goal-form button[type=submit]")
    wait_for(lambda: visible(page, "#confirm"), "the long-move confirmation")
    asked = text(page, "#confirm-text")
    assert f"target (10.01, -0.01, {far_z:.2f}) mm, distance 60.00 mm" in asked, asked
    page.click("#confirm-no")
    wait_for(lambda: "nothing was sent" in text(page, "#toast"), "the cancel said")
    assert not visible(page, "#confirm")
    type_goal(page, "10.01", "-0.01", f"{home[2] * 1000:.2f}")  # a short one: sent at once
    go_and_wait_sent(page, [0.01001, -0.00001, home[2]])
    assert len(page.goals) == sent + 1  # the cancelled one was never sent


def test_torque_off_while_moving_asks_first(page: Any, server: Server) -> None:
    page.select_option("#jog-speed", "20")
    page.check("#jog-keys")
    before = text(page, "#pos-goal")
    page.keyboard.down("ArrowLeft")
    try:
        wait_for(lambda: text(page, "#pos-goal") != before, "the page to see the arm jog")
        page.click("#torque-off")
        wait_for(lambda: visible(page, "#confirm"), "the torque-off confirmation")
        assert "The arm is moving" in text(page, "#confirm-text")
        page.click("#confirm-no")
    finally:
        page.keyboard.up("ArrowLeft")
    assert status(server)["torque"], "cancelled: the torque stays on"


def commanded_still(server: Server) -> bool:
    """The commanded point the same in two reads 0.2 s of loop time apart."""
    first = status(server)
    wait_for(lambda: status(server)["time_s"] > first["time_s"] + 0.2, "loop time")
    return status(server)["ee"]["commanded_m"] == first["ee"]["commanded_m"]


def measured_mm(server: Server) -> list[float]:
    return [v * 1000 for v in status(server)["ee"]["position_m"]]


def test_after_torque_off_no_error_and_the_preview_is_about_the_arm_now(
    page: Any, server: Server
) -> None:
    wait_for(lambda: commanded_still(server), "the jog to stop")
    wait_for(lambda: any(c.isdigit() for c in text(page, "#pos-err")), "an error with a setpoint")

    def torque_off() -> bool:
        if visible(page, "#confirm"):
            page.click("#confirm-yes")
        elif status(server)["torque"]:
            page.click("#torque-off")
        return not status(server)["torque"]

    wait_for(torque_off, "torque off")
    wait_for(lambda: text(page, "#pos-err") == "–", "the error blank without a setpoint")
    wait_for(lambda: visible(page, "#first-steps"), "the guidance back (torque is off)")

    # the relaxed arm falls below the workspace; the test preview names where it is now
    def preview_names_the_arm() -> bool:
        shown = text(page, "#run-preview")
        found = TRIPLE_MM.search(shown) if "there now" in shown else None
        if found is None:
            return False
        here = measured_mm(server)
        return all(abs(float(v) - h) < 5 for v, h in zip(found.groups(), here, strict=True))

    wait_for(preview_names_the_arm, "the preview to name the measured point, in mm", 60)
    shown = text(page, "#run-preview")
    assert "] m" not in shown and "POST" not in shown, shown
    assert text(page, "#pos-err") == "–"


def test_the_e_stop_toast_goes_after_reset(page: Any, server: Server) -> None:
    page.click("#estop")
    wait_for(lambda: status(server)["estopped"], "the server e-stopped")
    type_goal(page, "0", "0", "-240")
    page.click("#goal-form button[type=submit]")

    def refused_in_words() -> bool:
        if visible(page, "#confirm"):  # the relaxed arm is far: confirm, to meet the refusal
            page.click("#confirm-yes")
        return visible(page, "#toast") and "E-stop is active" in text(page, "#toast")

    wait_for(refused_in_words, "the refusal in the operator's words")
    toast = text(page, "#toast")
    assert toast == "E-stop is active: press Reset first.", toast
    assert "/api/reset" in page.locator("#toast").get_attribute("title")  # the server's words
    page.click("#reset")
    wait_for(lambda: not status(server)["estopped"], "the e-stop reset")
    wait_for(lambda: not visible(page, "#toast"), "the toast gone with its condition")


def test_a_conditional_toast_stays_while_its_condition_holds(page: Any) -> None:
    """The law behind the last test, without the clock: the toast goes on the first status
    asked after it was shown that says the condition cleared, and not before."""
    result = page.evaluate("""async () => {
        const ui = await import("/js/ui.js");
        const seen = () => !document.getElementById("toast").hidden;
        ui.showError({ message: "e-stop is active: POST /api/reset first", status: 409 });
        const shownAt = performance.now();
        const out = [seen()];
        ui.toastStatus({ estopped: false, faults: [] }, shownAt - 1); out.push(seen());
        ui.toastStatus({ estopped: true, faults: [] }, shownAt + 1); out.push(seen());
        ui.toastStatus({ estopped: false, faults: [] }, shownAt + 1); out.push(seen());
        return out;
    }""")
    assert result == [True, True, True, False]


def test_messages_speak_mm_degrees_and_buttons(page: Any) -> None:
    said = page.evaluate("""async () => {
        const { operatorText } = await import("/js/ui.js");
        return [
          "infeasible: joint 1: 100.0 deg outside its limits at t = 0.000 s, point " +
            "[0.0100, 0.0000, -0.3950] m; the robot is there now: move it into the workspace " +
            "first (a goal or jog)",
          'torque is off: POST /api/torque {"enabled": true} first',
          "fault: following error 0.5236 rad on joint 2; POST /api/reset first",
        ].map((m) => operatorText({ message: m, status: 409 }).text);
    }""")
    assert "point (10.0, 0.0, -395.0) mm" in said[0] and "(Go to or jog)" in said[0]
    assert said[1] == "Torque is off: press Torque on first."
    assert said[2] == "Fault: following error 30.0° on joint 2. Press Reset first."


def test_control_and_field_messages_carry_no_api_words(page: Any) -> None:
    """Issue 32 point 7: the server's own refusals (the lease's, a wrist angle's) in the
    page's words: no take_over, no POST, no lease id, no phi_rad."""
    from app.config import Settings
    from app.control.authority import Authority, ControlRefused
    from app.control.commands import CommandContext
    from app.control.errors import GoalRejected

    authority = Authority(None, 30.0)
    authority.take("bench laptop")
    messages = []
    for call in (lambda: authority.take("dashboard-x"), lambda: authority.check("wrong")):
        with pytest.raises(ControlRefused) as refused:
            call()
        messages.append(str(refused.value))
    with pytest.raises(GoalRejected) as rejected:  # no wrist: only phi = 0
        CommandContext.from_settings(Settings()).gate.check_phi(0.5)
    messages.append(str(rejected.value))
    assert "take_over" in messages[0] and "phi_rad" in messages[2]  # the API's words
    said = page.evaluate(
        """async (messages) => {
        const { operatorText } = await import("/js/ui.js");
        return messages.map((m) => operatorText({ message: m, status: 409 }).text);
    }""",
        messages,
    )
    assert said[0].startswith("Control is held by bench laptop (another tab or program)")
    assert said[1].startswith("Control is held by bench laptop")
    assert said[2].startswith("Wrist angle φ: no wrist axis")
    for text in said:
        for api_word in ("take_over", "POST", "/api/", "lease_id", "X-Lease", "phi_rad"):
            assert api_word not in text, (api_word, text)


def test_values_are_marked_stale_when_the_status_stops(page: Any) -> None:
    page_condition(page, "() => !document.body.classList.contains('stale')", "fresh values")
    page.route("**/api/status", lambda route: route.abort())
    try:
        page_condition(page, "() => document.body.classList.contains('stale')", "stale marking")
        assert "(stale)" in page.evaluate(
            "getComputedStyle(document.getElementById('pos-meas'), '::after').content"
        )
    finally:
        page.unroute("**/api/status")
    page_condition(page, "() => !document.body.classList.contains('stale')", "fresh again")


def test_sinusoid_fields_read_a_decimal_comma_and_refuse_what_is_not_a_number(
    page: Any, server: Server
) -> None:
    checks: list[dict] = []  # every preview request's body
    starts: list[dict] = []  # every run start's body

    def listen(request: Any) -> None:
        if request.method == "POST" and request.url.endswith("/api/tests/sinusoid/check"):
            checks.append(json.loads(request.post_data))
        elif request.method == "POST" and request.url.endswith("/api/tests/sinusoid"):
            starts.append(json.loads(request.post_data))

    def asked(amplitude_m: float) -> bool:
        text(page, "#run-preview")  # a call into Playwright: it delivers the page's events
        return any(c["amplitude_m"][0] == pytest.approx(amplitude_m) for c in checks)

    amp_x = page.locator("#run-form input[name=amplitude0]")
    page.on("request", listen)
    try:
        amp_x.fill("12,5")  # a decimal comma: 12.5 mm, never 125 mm nor 0
        wait_for(lambda: asked(0.0125), "a preview of 12.5 mm", seen=lambda: checks[-1:])
        assert amp_x.get_attribute("aria-invalid") == "false"
        amp_x.fill("1,2,5")  # not a number in any reading: refused, named, not sent
        wait_for(
            lambda: "amplitude x mm" in text(page, "#run-preview"),
            "the preview to name the bad field",
            seen=lambda: text(page, "#run-preview"),
        )
        assert "not a number" in text(page, "#run-preview")
        assert amp_x.get_attribute("aria-invalid") == "true"
        page.click("#run-start")
        wait_for(lambda: "Not started: amplitude x mm" in text(page, "#toast"), "the refusal")
        amp_x.fill("50")  # a later, harmless preview: what was asked before it has arrived
        wait_for(lambda: asked(0.05), "a preview of 50 mm", seen=lambda: checks[-1:])
    finally:
        page.remove_listener("request", listen)
    assert not starts, starts
    # every preview asked for 12.5 mm or 50 mm: nothing else was ever sent
    assert {round(c["amplitude_m"][0], 6) for c in checks} <= {0.0125, 0.05}, checks


def test_taking_control_from_another_client_is_asked_in_the_page(page: Any, server: Server) -> None:
    server.post("/api/lease", {"client": "bench laptop", "take_over": True})
    assert server.get("/api/lease")["holder"] == "bench laptop"
    page.click("#reset")  # a command: the lease is another's, so the page asks first
    wait_for(lambda: visible(page, "#confirm"), "the take-control question in the page")
    assert "bench laptop" in text(page, "#confirm-text")
    assert text(page, "#confirm-yes") == "Take control"
    # the page's own words: the API's "take it with take_over=true" stays in the API
    assert "take_over" not in text(page, "#confirm-text")
    page.click("#confirm-yes")
    wait_for(
        lambda: (server.get("/api/lease")["holder"] or "").startswith("dashboard-"),
        "the page to hold control",
        seen=lambda: server.get("/api/lease"),
    )

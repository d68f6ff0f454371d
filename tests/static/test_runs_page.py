"""The test-run panel in Debian's chromium against `deltadash serve` on the simulator: every
run type the API lists (GET /api/tests) chosen and started from the page with its fields in
mm, degrees, Hz and s, the body the page sent matched against the same values converted to
SI by hand; a field out of its bounds refused in the page's words with nothing sent, a
server's refusal with its field named as the page names it; abort; hold-in-world sent to its
own panel. What was sent is read from the requests the page made."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlparse

import pytest

from tests.static.test_servo_panel import at_rest_home
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


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    def listen(page: Any) -> None:
        page.sent = []  # (path, body) of every POST the page made under /api/tests/

        def record(request: Any) -> None:
            path = urlparse(request.url).path
            if request.method == "POST" and path.startswith("/api/tests/"):
                page.sent.append((path, json.loads(request.post_data or "null")))

        page.on("request", record)

    with dashboard_page(server, on_page=listen) as page:
        yield page


def sent(page: Any, path: str) -> list[Any]:
    page.evaluate("0")  # Playwright delivers the page's events during a call into it
    return [body for p, body in page.sent if p == path]


def text(page: Any, selector: str) -> str:
    return page.locator(selector).inner_text()


def shot(page: Any, name: str) -> None:
    panel = page.locator("section.tests")
    panel.evaluate("el => el.scrollIntoView({ block: 'center' })")  # clear of the header
    save_artifact(f"runs-page-{name}.png", panel.screenshot())


def choose(page: Any, name: str) -> None:
    wait_for(
        lambda: page.locator(f"#run-type option[value={name}]").count() == 1,
        "the run types listed",
        PAGE_WAIT_S,
    )
    page.select_option("#run-type", name)


def field(page: Any, label: str) -> Any:
    return page.locator(f"#run-fields [aria-label='{label}']")


def feasible(page: Any) -> None:
    waiting.wait_for(
        lambda: text(page, "#run-preview").rsplit(": ", 1)[-1] == "feasible",
        "the preview to say feasible",
        PAGE_WAIT_S,
        poll_s=0.1,
        seen=lambda: text(page, "#run-preview"),
    )


def still(server: Server) -> bool:
    """No run going, torque on, no fault, every joint still: where a run may start."""
    now = server.get("/api/status")
    speeds = now["joints"]["velocity_rad_s"]
    calm = all(v is not None and abs(v) < 0.02 for v in speeds)
    return now["mode"] in ("idle", "jog") and now["torque"] and not now["faults"] and calm


def start_and_finish(page: Any, server: Server, name: str) -> dict:
    """Start the chosen run from the page, wait for its end; the body the page sent."""
    wait_for(lambda: still(server), "the arm at rest", PAGE_WAIT_S, seen=server.brief)
    feasible(page)
    before = len(server.get("/api/runs"))
    page.click("#run-start")
    wait_for(
        lambda: len(server.get("/api/runs")) > before,
        f"the {name} run to start",
        PAGE_WAIT_S,
        seen=lambda: toasts(page),
    )
    run = server.get("/api/runs")[0]
    assert run["kind"] == name
    wait_for(
        lambda: server.get(f"/api/runs/{run['run_id']}")["state"] != "running",
        f"the {name} run to end",
        PAGE_WAIT_S,
    )
    assert server.get(f"/api/runs/{run['run_id']}")["state"] == "done"
    bodies = sent(page, f"/api/tests/{name}")
    assert len(bodies) == 1, bodies
    return bodies[0]


def test_each_run_type_starts_from_the_page_in_si(page: Any, server: Server) -> None:
    at_rest_home(page, server)

    # the sinusoid: amplitudes in mm, a phase in degrees, a decimal comma
    choose(page, "sinusoid")
    for label, typed in {
        "amplitude x mm": "20",
        "amplitude y mm": "12,5",
        "amplitude z mm": "30",
        "phase y deg": "90",
        "duration s": "1,5",
    }.items():
        field(page, label).fill(typed)
    shot(page, "sinusoid")
    body = start_and_finish(page, server, "sinusoid")
    assert body == {
        "amplitude_m": [0.02, 0.0125, 0.03],
        "frequency_hz": [1.0, 1.0, 2.0],
        "phase_rad": [0.0, pytest.approx(math.pi / 2, rel=1e-15), 0.0],
        "offset_m": [0.0, 0.0, -0.24],
        "duration_s": 1.5,
        "feedforward": False,
    }

    # the chirp: one axis chosen by name, its frequencies in Hz
    choose(page, "chirp")
    page.select_option("#run-fields select[name=axis]", label="y")
    field(page, "amplitude mm").fill("7,5")
    field(page, "start frequency Hz").fill("0,5")
    field(page, "end frequency Hz").fill("2")
    field(page, "duration s").fill("2")
    page.check("#run-fields input[name=feedforward]")
    shot(page, "chirp")
    body = start_and_finish(page, server, "chirp")
    assert body == {
        "axis": 1,
        "amplitude_m": 0.0075,
        "f0_hz": 0.5,
        "f1_hz": 2.0,
        "offset_m": [0.0, 0.0, -0.24],
        "duration_s": 2.0,
        "feedforward": True,
    }

    # the step: a 4 mm step down at 0.3 s
    choose(page, "step")
    field(page, "step size mm").fill("-4")
    field(page, "step at s").fill("0,3")
    field(page, "duration s").fill("1")
    body = start_and_finish(page, server, "step")
    assert body == {
        "axis": 2,
        "size_m": -0.004,
        "step_at_s": 0.3,
        "offset_m": [0.0, 0.0, -0.24],
        "duration_s": 1.0,
    }

    # the waypoints: the example's square, its last point removed, one point edited
    choose(page, "waypoints")
    rows = page.locator("#run-fields .run-points tbody tr")
    wait_for(lambda: rows.count() == 5, "the example's five points")
    page.click("#run-fields [aria-label='remove point 5']")
    field(page, "point 3 x mm").fill("15,5")
    page.click("#run-fields .run-add")  # a fifth point: the last one copied, a second later
    field(page, "point 5 y mm").fill("10")
    shot(page, "waypoints")
    body = start_and_finish(page, server, "waypoints")
    assert body == {
        "points_m": [
            [0.0, 0.0, -0.24],
            [0.03, 0.0, -0.24],
            [0.0155, 0.03, -0.24],
            [0.0, 0.03, -0.24],
            [0.0, 0.01, -0.24],
        ],
        "times_s": [0.0, 1.0, 2.0, 3.0, 4.0],
        "feedforward": False,
    }


def test_refusals_are_said_in_words_and_nothing_is_sent(page: Any, server: Server) -> None:
    before = len(page.sent)  # what the page sent in the tests before this one
    choose(page, "chirp")
    amplitude = field(page, "amplitude mm")
    amplitude.fill("300")  # over the chirp's 200 mm
    words = "amplitude mm: 300 mm is over the largest allowed, 200 mm"
    wait_for(lambda: text(page, "#run-preview") == words, "the bound said in the preview")
    assert amplitude.get_attribute("aria-invalid") == "true"
    page.click("#run-start")
    wait_for(lambda: f"Not started: {words}" in toasts(page), "the refusal in the toast")
    amplitude.fill("10")
    field(page, "duration s").fill("0")  # the run's length must be more than 0 s
    words = "duration s: must be more than 0 s"
    wait_for(lambda: text(page, "#run-preview") == words, "the duration's bound said")
    field(page, "duration s").fill("2")  # a harmless preview after the refused ones
    feasible(page)
    page.evaluate("0")
    since = page.sent[before:]
    assert not [b for p, b in since if p == "/api/tests/chirp"]
    assert all(b["amplitude_m"] <= 0.2 for p, b in since if p == "/api/tests/chirp/check")

    # what only the server can say (the step inside the run) comes back with the field as
    # the page names it, never the API's name
    choose(page, "step")
    field(page, "step at s").fill("3")
    field(page, "duration s").fill("1")
    wait_for(
        lambda: "step at (s): 3 s is not before" in text(page, "#run-preview").lower(),
        "the server's refusal naming the field",
        seen=lambda: text(page, "#run-preview"),
    )
    assert "step_at_s" not in text(page, "#run-preview")
    page.click("#run-start")
    wait_for(
        lambda: any(t.lower().startswith("not started: step at (s)") for t in toasts(page)),
        "the start's refusal in words",
        seen=lambda: toasts(page),
    )
    page.evaluate("0")
    starts = [b for p, b in page.sent[before:] if p == "/api/tests/step"]
    assert [b["step_at_s"] for b in starts] == [3.0]  # sent, and refused by the server
    assert not [r for r in server.get("/api/runs") if r["state"] == "running"]
    field(page, "step at s").fill("0,5")


def test_a_run_is_aborted_from_the_page(page: Any, server: Server) -> None:
    at_rest_home(page, server)
    choose(page, "sinusoid")
    field(page, "duration s").fill("60")
    wait_for(lambda: still(server), "the arm at rest", PAGE_WAIT_S, seen=server.brief)
    feasible(page)
    before = len(server.get("/api/runs"))
    page.click("#run-start")
    wait_for(lambda: len(server.get("/api/runs")) > before, "the run to start", PAGE_WAIT_S)
    run_id = server.get("/api/runs")[0]["run_id"]
    abort = page.locator("#run-abort")
    wait_for(lambda: abort.is_enabled(), "Abort offered while the run goes", PAGE_WAIT_S)
    wait_for(lambda: "run " + run_id in text(page, "#run-phase"), "the run's progress shown")
    shot(page, "running")
    abort.click()
    wait_for(
        lambda: server.get(f"/api/runs/{run_id}")["state"] == "aborted",
        "the run aborted",
        PAGE_WAIT_S,
    )
    wait_for(lambda: abort.is_disabled(), "Abort gone with the run", PAGE_WAIT_S)


def test_hold_in_world_is_sent_to_its_own_panel(page: Any) -> None:
    choose(page, "hold")
    assert page.locator("#run-form").is_hidden() and page.locator("#run-start").is_hidden()
    assert page.locator("#run-hold-go").is_visible()
    assert text(page, "#run-doc") == ""  # no other type's description under it
    shot(page, "hold")
    page.click("#run-hold-go")
    panel = page.locator("section.hold, #hold")
    if panel.count():  # the Hold-in-world panel (static/js/hold.js) in view
        wait_for(lambda: panel.first.is_visible(), "the hold panel in view")
    else:
        wait_for(lambda: "not on this page" in text(page, "#run-hold-said"), "said it is not here")
    choose(page, "sinusoid")
    assert page.locator("#run-form").is_visible()

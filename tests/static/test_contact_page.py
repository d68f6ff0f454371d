"""Contact from the page (issue 33), in Debian's chromium against `deltadash serve` on the
twin with a plate 260 mm under the base: the live force estimate and the limits shown; bad
values refused in words with nothing sent; a touch typed in N, mm/s and mm sent in SI (checked
against hand-converted values), ending "contact" with the contact point shown where MuJoCo's
plate is (its face at -260 mm plus the tip's 1 mm radius); a press sent in SI; Stop (POST
/api/stop, not the e-stop) ends it. What was sent is read from the requests the page made."""

from __future__ import annotations

import json
import re
import time
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlparse

import pytest

from tests.support import wait as waiting
from tests.support.browser import (
    PAGE_WAIT_S,
    PATIENT_SIM_ENV,
    browser_skip_reason,
    dashboard_page,
    plots_frame,
    save_artifact,
    toasts,
)
from tests.support.server import Server, serve

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
WATCHED = ("/api/contact/touch", "/api/contact/press", "/api/stop")
PLATE_Z_MM = -260.0
TIP_RADIUS_MM = 1.0  # hardware/sim/surfaces.py: the tip's sphere touches at its radius
SURFACE_Z_MM = PLATE_Z_MM + TIP_RADIUS_MM  # -259.0: the tip's centre at first contact


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[Server]:
    """The page's server on the twin with one plate (normal +z) at z = -0.26 m."""
    env = {**PATIENT_SIM_ENV, "DELTADASH_HARDWARE__SIM__PLATES": '[{"point_m": [0, 0, -0.26]}]'}
    with serve(tmp_path_factory.mktemp("contact"), **env) as served:
        yield served


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    def listen(page: Any) -> None:
        page.sent = []
        page.on("request", lambda r: record(page, r))

    with dashboard_page(server, on_page=listen) as page:
        yield page


def record(page: Any, request: Any) -> None:
    path = urlparse(request.url).path
    if request.method == "POST" and path.startswith(WATCHED):
        body = json.loads(request.post_data) if request.post_data else None
        page.sent.append((path, body))


def sent(page: Any, path: str) -> list[Any]:
    page.evaluate("0")  # Playwright delivers the page's events during a call into it
    return [body for p, body in page.sent if p == path]


def text(page: Any, selector: str) -> str:
    return page.locator(selector).inner_text()


def shown(page: Any, server: Server) -> Any:
    """What a timed-out wait prints: the robot, the panel's texts and the messages."""
    ids = ("mag", "force", "std", "why", "limits", "outcome", "point", "peak", "mode")
    panel = page.evaluate(
        f"() => Object.fromEntries({json.dumps(ids)}.map("
        "(k) => [k, document.getElementById(`contact-${k}`).textContent]))"
    )
    return {"robot": server.brief(), "panel": panel, "toasts": toasts(page)[-3:]}


def at_home(page: Any, server: Server) -> None:
    """Torque on and the arm at the home point (0, 0, -240) mm, by the page's own buttons."""
    clicked = [-1e9]

    def on() -> bool:
        if server.get("/api/status")["torque"]:
            return True
        if time.monotonic() - clicked[0] > 2.0:
            clicked[0] = time.monotonic()
            page.click("#torque-on")
        return False

    waiting.wait_for(on, "torque on", PAGE_WAIT_S, poll_s=0.2, seen=server.brief)
    for axis, value in zip("xyz", ("0", "0", "-240"), strict=True):
        page.fill(f"#goal-form input[name={axis}]", value)
    page.click("#goal-form button[type=submit]")

    def arrived() -> bool:
        if page.locator("#confirm").is_visible():
            page.click("#confirm-yes")
        status = server.get("/api/status")
        return abs(status["ee"]["position_m"][2] + 0.24) < 1e-3

    waiting.wait_for(arrived, "the arm at the home point", PAGE_WAIT_S, seen=server.brief)


def touch_from_page(page: Any, server: Server, retract: str) -> dict:
    """From the home point, a touch down to 2 N typed and sent from the page, followed to
    its end as the page shows it; the server's record of it (each test makes its own: the
    suite runs tests in any order). A touch the loaded machine stopped (a late heartbeat is
    a lost link, a starved simulator a stale-feedback fault: its ``reason`` says which) is
    reset and made again, as an operator would, up to three times."""
    for _ in range(3):
        touch = _one_touch(page, server, retract)
        if touch["outcome"] != "stopped":
            return touch
        print(f"touch stopped ({touch.get('reason')}): again")
        if server.get("/api/status")["mode"] in ("fault", "estop"):
            page.click("#reset")
            waiting.wait_for(
                lambda: server.get("/api/status")["mode"] not in ("fault", "estop"),
                "the reset",
                PAGE_WAIT_S,
                seen=server.brief,
            )
    return touch


def _one_touch(page: Any, server: Server, retract: str) -> dict:
    at_home(page, server)
    before = server.get("/api/contact")["touch"]
    requests = len(sent(page, "/api/contact/touch"))
    fill_touch(page, "2", "10", "50", retract)
    page.select_option("#contact-touch-dir", "-z")
    page.click("#contact-touch-go")
    waiting.wait_for(
        lambda: len(sent(page, "/api/contact/touch")) > requests,
        "the touch sent",
        PAGE_WAIT_S,
        seen=server.brief,
    )

    def ended() -> bool:
        touch = server.get("/api/contact")["touch"]
        return (
            touch is not None
            and touch != before
            and touch["outcome"] != "touching"
            and server.get("/api/status")["mode"] != "touch"
            and text(page, "#contact-outcome") == touch["outcome"]
        )

    seen = lambda: shown(page, server)  # noqa: E731
    waiting.wait_for(ended, "the touch's end shown", 3 * PAGE_WAIT_S, seen=seen)
    return server.get("/api/contact")["touch"]


def fill_touch(page: Any, force: str, speed: str, travel: str, retract: str) -> None:
    for field, value in (("force-n", force), ("speed", speed), ("travel", travel)):
        page.fill(f"#contact-touch-{field}", value)
    page.fill("#contact-touch-retract", retract)


def test_the_estimate_and_the_limits_are_shown(page: Any, server: Server) -> None:
    at_home(page, server)
    page.locator("#contact-h").scroll_into_view_if_needed()
    waiting.wait_for(
        lambda: (
            page.locator("#contact-live").get_attribute("data-valid") == "true"
            and text(page, "#contact-force") != "–"
        ),
        "the estimate shown",
        PAGE_WAIT_S,
        seen=lambda: shown(page, server),
    )

    # at rest in free air the estimate settles near zero (within 3 sigma + 0.05 N, as the
    # API test has it), and the page shows the status's numbers: F, |F| and the 1-sigma [N]
    def settled() -> bool:
        c = server.get("/api/status")["contact"]
        return c["valid"] and all(
            abs(f) <= 3 * s + 0.05 for f, s in zip(c["force_n"], c["std_n"], strict=True)
        )

    seen = lambda: shown(page, server)  # noqa: E731
    waiting.wait_for(settled, "the estimate at rest", PAGE_WAIT_S, seen=seen)

    def page_shows_status() -> bool:
        c = server.get("/api/status")["contact"]
        force = [float(v) for v in text(page, "#contact-force").split(",")]
        std = [float(v) for v in text(page, "#contact-std").removeprefix("± ").split(",")]
        return force == pytest.approx(c["force_n"], abs=0.1) and std == pytest.approx(
            c["std_n"], abs=0.02
        )

    waiting.wait_for(page_shows_status, "the status's estimate shown", PAGE_WAIT_S, seen=seen)
    assert text(page, "#contact-mag").endswith(" N")
    limits = server.get("/api/contact")["limits"]
    assert f"force limit {limits['force_limit_n']:.1f} N" in text(page, "#contact-limits")
    # the defaults (GET /api/contact, SI) shown in the form's units
    assert page.input_value("#contact-touch-speed") == "10"
    assert page.input_value("#contact-touch-travel") == "50"


def test_no_estimate_is_said_with_its_reason(page: Any) -> None:
    """A status whose estimate is not valid: the panel says why, and shows no numbers (drawn
    from a status given to the panel's own listener, read back in the same call)."""
    said = page.evaluate(
        """async () => {
            const { onContactStatus } = await import("./js/contact.js");
            const none = [null, null, null];
            onContactStatus({ mode: "idle", contact: { valid: false, magnitude_n: null,
              reason: "leg 2: current not read", force_n: none, std_n: none } });
            const shown = (k) => document.getElementById(`contact-${k}`).textContent;
            return ["why", "force", "mag"].map(shown);
        }"""
    )
    assert said == ["no estimate: leg 2: current not read", "–", "–"]


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("force-n", "40", "Touch force must be at most 15 N"),
        ("force-n", "0,5", "Touch force must be over 0.8 N"),
        ("speed", "1,2,5", 'Touch speed "1,2,5" is not a number'),
        ("speed", "150", "Touch speed must be at most 100 mm/s"),
        ("travel", "0", "Max travel must be over 0 mm"),
        ("retract", "60", "Retract must be at most 50 mm"),
    ],
)
def test_a_bad_value_is_refused_without_a_request(
    page: Any, server: Server, field: str, value: str, words: str
) -> None:
    before = len(sent(page, "/api/contact/touch"))
    fill_touch(page, "2", "10", "50", "0")
    page.fill(f"#contact-touch-{field}", value)
    page.click("#contact-touch-go")
    waiting.wait_for(
        lambda: any(words in t and "nothing was sent" in t for t in toasts(page)),
        f"the refusal {words!r}",
        PAGE_WAIT_S,
        seen=lambda: shown(page, server),
    )
    assert page.locator(f"#contact-touch-{field}").get_attribute("aria-invalid") == "true"
    assert len(sent(page, "/api/contact/touch")) == before


def test_a_refusal_of_the_server_is_said_in_the_pages_words(page: Any, server: Server) -> None:
    """300 mm down from the home point is outside the workspace: the page cannot know it,
    the server refuses it (422 naming max_travel_m in m), the page says it in mm and the
    form's words, and nothing moves."""
    at_home(page, server)
    before = server.get("/api/contact")["touch"]
    fill_touch(page, "2", "10", "300", "0")
    page.click("#contact-touch-go")
    said = re.compile(
        r"Touch refused: Max travel: the touch's end \(-?0\.0, -?0\.0, -540\.0\) mm is outside"
    )
    waiting.wait_for(
        lambda: any(said.match(t) for t in toasts(page)),
        "the refusal in the page's words",
        PAGE_WAIT_S,
        seen=lambda: shown(page, server),
    )
    assert sent(page, "/api/contact/touch")[-1]["max_travel_m"] == pytest.approx(0.3, abs=1e-15)
    assert server.get("/api/contact")["touch"] == before
    assert server.get("/api/status")["mode"] != "touch"


def test_a_touch_from_the_page_finds_the_plate(page: Any, server: Server) -> None:
    touch = touch_from_page(page, server, retract="2")
    # hand-converted: 10 mm/s = 0.01 m/s, 50 mm = 0.05 m, 2 mm = 0.002 m
    body = sent(page, "/api/contact/touch")[-1]
    assert body == {
        "direction": [0, 0, -1],
        "force_n": 2,
        "speed_m_s": pytest.approx(0.01, abs=1e-15),
        "max_travel_m": pytest.approx(0.05, abs=1e-15),
        "retract_m": pytest.approx(0.002, abs=1e-15),
    }
    assert touch["outcome"] == "contact", (touch, shown(page, server))
    point_mm = [float(v) for v in text(page, "#contact-point").split(",")]
    assert point_mm[2] == pytest.approx(SURFACE_Z_MM, abs=0.3), shown(page, server)
    # what is shown is the server's point, to the 0.01 mm shown
    assert point_mm == pytest.approx([1e3 * c for c in touch["contact_point_m"]], abs=0.006)
    peak = float(text(page, "#contact-peak").removesuffix(" N"))
    # the peak as the server has it: at least the set force, never the limit (15 N). How far
    # over the set force is the API's and the benchmark's (a real-time server on a loaded
    # machine overshoots more than the simulated-time API test: 5.4 N seen here)
    assert peak == pytest.approx(touch["peak_force_n"], abs=0.006) and 2.0 <= peak < 15.0
    assert any(t.startswith("Touch: contact at") for t in toasts(page))
    path = save_artifact("contact_panel.png", page.locator("section.contact").screenshot())
    print(f"screenshot: {path}")


DRAWN = """() => { const p = document.getElementById('plot');
  const l = p.layout, y = (n) => l['yaxis' + (n === 1 ? '' : n)];
  return { titles: [1, 2, 3, 4, 5, 6].map((n) => y(n).title.text), names: p.data.map((d) => d.name),
           visible: p.data.map((d) => d.visible !== false), y: p.data.map((d) => d.y) }; }"""


def test_the_touch_force_is_in_the_plots(page: Any, server: Server) -> None:
    """Right after the touch (which pressed 2 N down, the peak in GET /api/contact): the
    plots' "tip force" set draws x, y, z and their 1-sigma, and its z trace went down to
    the pressed force within the last 30 s."""
    touch_from_page(page, server, retract="2")
    plots = plots_frame(page)
    plots.select_option("#plot-window", "30")
    plots.select_option("#plot-signals", "force")
    waiting.wait_for(
        lambda: plots.evaluate(DRAWN)["titles"][0] == "tip force x [N]", "the tip force plots"
    )
    shown = plots.evaluate(DRAWN)
    assert shown["titles"] == [
        *(f"tip force {a} [N]" for a in "xyz"),
        *(f"1σ {a} [N]" for a in "xyz"),
    ]
    assert shown["visible"][:3] == [False, True, True]  # no goal trace for a force
    peak = server.get("/api/contact")["touch"]["peak_force_n"]
    z = [v for v in shown["y"][7] if v is not None]  # column z, slot "force"
    sigma = [v for v in shown["y"][8] if v is not None]
    assert z and min(z) <= -1.5 and min(z) >= -(peak + 0.5), (min(z), peak)
    assert sigma and all(0 < v < 1 for v in sigma)
    save_artifact("contact_plots.png", page.locator("#plots-frame").screenshot())
    plots.select_option("#plot-signals", "position")


def test_a_press_is_sent_in_si_and_stop_ends_it_without_an_e_stop(
    page: Any, server: Server
) -> None:
    # a press starts on the surface: a touch with retract 0 leaves the tip there
    assert touch_from_page(page, server, retract="0")["outcome"] == "contact"
    presses, stops = len(sent(page, "/api/contact/press")), len(sent(page, "/api/stop"))
    page.select_option("#contact-press-dir", "-z")
    page.fill("#contact-press-force", "3")
    page.fill("#contact-press-duration", "20")
    page.click("#contact-press-go")
    waiting.wait_for(
        lambda: len(sent(page, "/api/contact/press")) > presses,
        "the press sent",
        PAGE_WAIT_S,
        seen=server.brief,
    )
    body = sent(page, "/api/contact/press")[-1]
    assert body == {"direction": [0, 0, -1], "force_n": 3, "frame": "base", "duration_s": 20}
    waiting.wait_for(
        lambda: (
            server.get("/api/status")["mode"] == "press"
            and text(page, "#contact-mode") == "pressing"
        ),
        "the press running and shown",
        PAGE_WAIT_S,
        seen=lambda: shown(page, server),
    )
    page.click("#contact-stop")
    waiting.wait_for(
        lambda: server.get("/api/status")["mode"] == "idle",
        "stopped",
        PAGE_WAIT_S,
        seen=server.brief,
    )
    status = server.get("/api/status")
    assert not status["estopped"] and status["torque"]  # a stop, not an e-stop
    assert sent(page, "/api/stop")[stops:] == [{}]

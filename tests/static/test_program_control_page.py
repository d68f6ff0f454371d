"""The program's motion control row (static/js/programcontrol.js) in Debian's chromium against
`deltadash serve` on the simulator: a program run from the page stops at its M0 (the line
stays marked), the feed override slider sends its value and the time left follows, Step
stops at the end of the line, Pause stands on the line, Resume goes on, and a run from a
line starts there; a "run from line" that is not a line number sends nothing. What the page
shows is compared with what GET /api/runs says; what it sent is read from its requests."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlparse

import pytest

from tests.static.test_programs_page import check, click_until, known_state, seen, until
from tests.support.browser import browser_skip_reason, dashboard_page, save_artifact, toasts
from tests.support.server import Server

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
# from the middle, relative moves at 2 mm/s: line 2 goes 8 mm along x (4 s), line 3 is an
# M0, lines 4 and 5 go 8 mm out and back along y, line 6 back along x: it ends where it began
PROGRAM = "G21 G91 F120\nG1 X8\nM0\nG1 Y8\nG1 Y-8\nG1 X-8\nM2\n"


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    def listen(page: Any) -> None:
        page.sent = []  # (method, path, body) of the page's requests to the programs routes
        page.on("request", lambda r: record(page, r))

    with dashboard_page(server, on_page=listen) as page:
        yield page


def record(page: Any, request: Any) -> None:
    path = urlparse(request.url).path
    if path.startswith("/api/programs/") and request.method in ("POST", "PUT"):
        body = json.loads(request.post_data) if request.post_data else None
        page.sent.append((request.method, path, body))


def sent(page: Any, method: str, path: str) -> list[Any]:
    page.evaluate("0")  # Playwright delivers the page's events during a call into it
    return [body for m, p, body in page.sent if m == method and p == path]


def program_run(server: Server) -> dict[str, Any] | None:
    """The program run going on, as GET /api/runs has it (None: none)."""
    runs = server.get("/api/runs")
    return next((r for r in runs if r["state"] == "running" and r["kind"] == "program"), None)


def shown(page: Any) -> dict[str, str]:
    """What the row shows: its state line, its paused flag and line, the time left."""
    state = page.locator("#pc-state")
    return {
        "state": state.inner_text(),
        "paused": state.get_attribute("data-paused") or "",
        "line": state.get_attribute("data-line") or "",
        "left": page.locator("#pc-left").inner_text(),
        "pause_button": page.locator("#pc-pause").inner_text(),
        "running_band": page.locator("#prog-text").get_attribute("data-running-line") or "",
    }


def look(server: Server, page: Any):
    base = seen(server, page)

    def brief() -> dict[str, Any]:
        out = base()
        out["row"] = shown(page)
        run = program_run(server)
        out["progress"] = run and run["progress"]
        return out

    return brief


def stands_at(page: Any, server: Server, reason: str, line: int) -> dict[str, Any]:
    """Wait until the page and the server both say the program stands for ``reason`` on
    ``line``; the server's progress then."""

    def both() -> dict[str, Any] | None:
        run = program_run(server)
        progress = run and run["progress"]
        row = shown(page)
        if not progress or progress.get("paused") != reason or progress.get("feed_rate") != 0:
            return None
        if row["state"] != f"paused: {reason}" or row["line"] != str(line):
            return None
        return progress

    return until(both, f"the program standing: {reason} (line {line})", look(server, page))


def test_a_program_is_paused_stepped_slowed_and_run_from_a_line_from_the_page(page, server):
    known_state(page, server)
    brief = look(server, page)
    assert check(page, server, PROGRAM).startswith("passes"), shown(page)
    assert page.locator("#pc-pause").is_disabled() and page.locator("#pc-step").is_disabled()

    # a "run from line" that is not a line number: said, and nothing is sent
    page.fill("#pc-from", "2,5")
    page.click("#prog-run")
    until(lambda: "not started" in shown(page)["state"], "the refusal", brief)
    assert "run from line" in shown(page)["state"] and not sent(page, "POST", "/api/programs/run")
    assert page.locator("#pc-from").get_attribute("aria-invalid") == "true"
    page.fill("#pc-from", "")

    # Run: the M0 on line 3 stops it there; the page shows it paused on line 3
    click_until(page, "#prog-run", lambda: program_run(server), "the program's run", brief)
    assert sent(page, "POST", "/api/programs/run")[-1]["feed_override"] == 1.0
    at_m0 = stands_at(page, server, "M0 at line 3: press Resume", 3)
    assert at_m0["program_line"] == 3
    until(lambda: shown(page)["running_band"] == "3", "line 3 marked in the text", brief)
    assert shown(page)["pause_button"] == "Resume"
    save_artifact("program_control_m0.png", page.screenshot(full_page=False))
    save_artifact("program_control_panel.png", page.locator("section.programs").screenshot())

    # the feed override slider: 50 % is sent, the server says it, the time left doubles
    page.locator("#pc-feed").fill("50")
    until(lambda: sent(page, "PUT", "/api/programs/feed"), "the feed override sent", brief)
    assert sent(page, "PUT", "/api/programs/feed")[-1] == {"override": 0.5}
    assert page.locator("#pc-feed-out").inner_text() == "50 %"
    slowed = until(
        lambda: (r := program_run(server)) and r["progress"]["feed_override"] == 0.5 and r,
        "the feed override at the server",
        brief,
    )
    assert slowed["progress"]["time_left_s"] == pytest.approx(2 * at_m0["time_left_s"], rel=0.01)
    seconds = round(slowed["progress"]["time_left_s"])
    minutes, rest = divmod(seconds, 60)
    until(
        lambda: shown(page)["left"] == f"time left {minutes}:{rest:02d} after Resume",
        "the page's time left",
        brief,
    )

    # Step: line 4 to its end, and it stands there
    page.click("#pc-step")
    stands_at(page, server, "single step: stopped at the end of line 4", 4)
    assert sent(page, "POST", "/api/programs/step") == [None]

    # Resume, then Pause on line 5: it stands on that line, its point still
    page.click("#pc-pause")
    until(lambda: shown(page)["line"] == "5" and shown(page)["paused"] == "false", "line 5", brief)
    page.click("#pc-pause")
    paused = stands_at(page, server, "paused", 5)
    assert paused["program_line"] == 5
    goal = server.get("/api/status")["goal"]["position_m"]
    ticks = server.get("/api/status")["loop"]["ticks"]
    until(lambda: server.get("/api/status")["loop"]["ticks"] > ticks + 50, "50 ticks", brief)
    assert server.get("/api/status")["goal"]["position_m"] == goal
    assert shown(page)["running_band"] == "5"

    # Resume: to its end at 50 %
    page.click("#pc-pause")
    until(lambda: program_run(server) is None, "the program's end", brief)
    until(lambda: shown(page)["state"] == "no program running", "the row idle", brief)

    # run from line 4 (the check still speaks for this text): it starts on line 4
    page.fill("#pc-from", "4")
    click_until(page, "#prog-run", lambda: program_run(server), "the run from line 4", brief)
    body = sent(page, "POST", "/api/programs/run")[-1]
    assert body["start_line"] == 4 and body["feed_override"] == 0.5
    run = program_run(server)
    assert run is not None and run["params"]["start_line"] == 4
    first = until(
        lambda: (r := program_run(server)) is None or (r["progress"] or {}).get("program_line"),
        "the first line of the run from line 4",
        brief,
    )
    assert first is True or first >= 4
    until(lambda: program_run(server) is None, "the run from line 4 to end", brief)
    assert not [t for t in toasts(page) if "not done" in t]

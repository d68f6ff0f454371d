"""The dashboard's program panel in Debian's chromium against `deltadash serve` (issue 18).

One page: a failing program checked (violations by line: each line's first cause, the others
folded under a "+N more" button; a click marks the line), a passing
circle (Run enabled; an edit disables it until checked again), an unreadable program (its
line and word), the running line of a program run (GET /api/runs answered by the test:
the server side of runs is its own branch), and the keys: Space typed in the program text
is a space, never an e-stop; Esc there e-stops. Each test starts from a known state: no
e-stop, torque on, the platform at the middle of the workspace (0, 0, -240) mm, where the
examples start.
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

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
EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
MIDDLE_M = (0.0, 0.0, -0.24)
# Press Check unless its answer number ``before`` has been passed or a check is running.
CLICK_CHECK = """(before) => {
  const answers = Number(document.getElementById("prog-result").dataset.answers || 0);
  const button = document.getElementById("prog-check");
  if (answers > before || button.disabled) return false;
  button.click();
  return true;
}"""
RETRY_S = 10.0  # a click with no effect this long is tried again (a busy page may lose it)


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    with dashboard_page(server) as page:
        yield page


def seen(server: Server, page: Any) -> Callable[[], dict[str, Any]]:
    """What a timed-out wait prints: the robot, the panel's result and the page's messages."""

    def brief() -> dict[str, Any]:
        out = server.brief()
        try:
            out["result"] = page.locator("#prog-result").inner_text(timeout=5_000)
            out["state"] = page.locator("#prog-state").inner_text(timeout=5_000)
        except Exception as exc:  # a page busy past the try: say so, not fail the report
            out["result"] = f"unreadable: {exc}"
        out["messages"] = toasts(page)
        return out

    return brief


def until(condition: Callable[[], Any], what: str, look: Callable[[], Any]) -> Any:
    """wait_for with the page's generous bound, printing ``look()`` on a timeout."""
    return wait_for(condition, what, PAGE_WAIT_S, seen=look)


def click_until(page: Any, selector: str, done: Callable[[], Any], what: str, look: Any) -> Any:
    """Click ``selector`` until ``done()`` is truthy, again after RETRY_S without effect."""
    clicked = [float("-inf")]

    def effect() -> Any:
        result = done()
        if result:
            return result
        if time.monotonic() - clicked[0] > RETRY_S and page.locator(selector).is_enabled():
            page.click(selector, timeout=PAGE_WAIT_S * 1e3)
            clicked[0] = time.monotonic()
        return None

    return until(effect, what, look)


def status(server: Server) -> dict[str, Any]:
    return server.get("/api/status")


def near_the_middle(point: list[float | None] | None, tolerance_m: float) -> bool:
    return point is not None and all(
        v is not None and abs(v - w) < tolerance_m for v, w in zip(point, MIDDLE_M, strict=True)
    )


def at_the_middle(server: Server) -> bool:
    """Holding the middle: the check starts from the commanded point while torque holds
    (the measured one sags by a millimetre or so under gravity, more on a loaded machine)."""
    s = status(server)
    return (
        s["torque"]
        and not s["estopped"]
        and s["mode"] not in ("move", "test")
        and near_the_middle(s["ee"]["commanded_m"], 1e-4)
        and near_the_middle(s["ee"]["position_m"], 0.01)
    )


def known_state(page: Any, server: Server) -> None:
    """No e-stop, torque on, the platform at the middle; the page's panel started."""
    look = seen(server, page)
    until(lambda: page.locator("#prog-gutter span").count() > 0, "the program panel", look)
    click_until(page, "#reset", lambda: not status(server)["estopped"], "no e-stop", look)
    click_until(page, "#torque-on", lambda: status(server)["torque"], "torque on", look)
    if at_the_middle(server):
        return
    for axis, value in zip("xyz", (0.0, 0.0, -240.0), strict=True):
        page.fill(f"#goal-form input[name={axis}]", f"{value:.2f}")

    def arrived() -> bool:  # from the hanging arm it is a long move: confirm it
        if page.locator("#confirm").is_visible():
            page.click("#confirm-yes", timeout=PAGE_WAIT_S * 1e3)
        return at_the_middle(server)

    click_until(page, "#goal-form button[type=submit]", arrived, "the middle (0, 0, -240)", look)


def check(page: Any, server: Server, text: str | None) -> str:
    """Put ``text`` in the program box (None: keep what is there), press Check; the panel's
    fresh answer."""
    if text is not None:
        page.fill("#prog-text", text)
    result = page.locator("#prog-result")
    before = int(result.get_attribute("data-answers") or 0)
    clicked = [float("-inf")]

    def answered() -> bool:
        if int(result.get_attribute("data-answers") or 0) > before:
            return True
        # (again after RETRY_S: a busy page may lose a click) in the page, in one step:
        # never once the answer is in, else a second check's "checking…" replaces it
        if time.monotonic() - clicked[0] > RETRY_S and page.evaluate(CLICK_CHECK, before):
            clicked[0] = time.monotonic()
        return False

    until(answered, "the check's answer", seen(server, page))
    return result.inner_text()


def marked_line(page: Any) -> str:
    return page.locator("#prog-text").get_attribute("data-marked-line") or ""


def test_a_failing_program_shows_its_violations_by_line(page: Any, server: Server) -> None:
    known_state(page, server)
    text = (EXAMPLES / "fails.ngc").read_text()
    answer = check(page, server, text)
    assert answer.startswith("fails"), answer
    rows = page.locator("#prog-violation-rows tr")
    lines = {int(n) for n in rows.evaluate_all("rs => rs.map(r => r.dataset.line)")}
    assert lines == {5, 6}  # the climb through the ceiling and the way back (docs/gcode.md)
    assert "mm" in page.locator("#prog-violation-rows").inner_text()  # operator units
    assert page.locator("#prog-run").is_disabled()  # a failing program never runs

    # one row per move's first cause (docs/gcode.md), the other five of each folded under it
    shown = page.locator("#prog-violation-rows tr:not([hidden])")
    first = "rs => rs.map(r => [r.dataset.line, r.cells[1].textContent])"
    assert shown.evaluate_all(first) == [["5", "joint_limit"], ["6", "workspace"]]
    # from where the robot holds (within 0.1 mm of the CLI's start): -76.6 deg, 42.2 beyond
    said = shown.first.inner_text()
    assert re.search(
        r"joint 1 reaches -7\d\.\d deg, 4\d\.\d deg beyond its lower limit -34\.4 deg", said
    )
    assert "10 more folded" in answer
    more = page.locator("#prog-violation-rows tr[data-line='5'] button[data-more]")
    assert more.inner_text() == "+5 more"
    more.click()  # unfolds line 5's others under its first cause (and marks line 5)
    until(lambda: shown.count() == 7, "line 5 unfolded", lambda: shown.evaluate_all(first))
    unfolded = shown.evaluate_all(first)
    assert unfolded[0] == ["5", "joint_limit"] and unfolded[-1] == ["6", "workspace"]
    assert {line for line, _ in unfolded[1:-1]} == {"5"}
    assert {kind for _, kind in unfolded[1:-1]} == {
        "workspace",
        "joint_acceleration",
        "torque",
        "ik",
        "ceiling",
    }
    assert more.get_attribute("aria-expanded") == "true" and more.inner_text() == "fold 5"
    more.click()  # and folds them again
    until(lambda: shown.count() == 2, "line 5 folded", lambda: shown.evaluate_all(first))

    page.locator("#prog-violation-rows tr[data-line='6']").first.click()
    until(lambda: marked_line(page) == "6", "line 6 marked", lambda: marked_line(page))
    assert page.locator("#prog-gutter span[data-line='6']").get_attribute("class") == "marked"
    assert page.locator("#prog-mark").is_visible()
    selected = page.evaluate(
        "() => { const t = document.getElementById('prog-text');"
        " return t.value.substring(t.selectionStart, t.selectionEnd); }"
    )
    assert selected == text.split("\n")[5]  # the 6th line itself

    # the 2D views draw the checked path and one red mark per violation
    for canvas in ("#ws-top", "#ws-side"):
        until(
            lambda c=canvas: (
                page.locator(c).get_attribute("data-program-violations") == str(rows.count())
            ),
            f"the violations drawn in {canvas}",
            lambda c=canvas: page.locator(c).evaluate("e => ({...e.dataset})"),
        )
        assert int(page.locator(canvas).get_attribute("data-program-points")) > 100
    for part, name in ((".programs", "program-panel"), (".workspace2d", "program-2d")):
        shot = page.locator(part).screenshot(timeout=PAGE_WAIT_S * 1e3)
        save_artifact(f"dashboard-{name}.png", shot)


def test_a_passing_program_enables_run_until_it_is_edited(page: Any, server: Server) -> None:
    known_state(page, server)
    page.fill("#prog-text", "")
    page.set_input_files("#prog-file", str(EXAMPLES / "circle.ngc"))  # opened as a file
    text = (EXAMPLES / "circle.ngc").read_text()
    box = page.locator("#prog-text")
    until(lambda: box.input_value() == text, "the file in the text box", box.input_value)
    assert page.locator("#prog-file-name").inner_text() == "circle.ngc"
    answer = check(page, server, None)
    assert answer.startswith("passes"), answer
    assert page.locator("#prog-violations").is_hidden()
    figures = page.locator("#prog-figures").inner_text()
    assert "path length" in figures and "peak joint speed" in figures and "torque" in figures
    assert page.locator("#prog-run").is_enabled()

    page.locator("#prog-text").press("End")  # an edit, even a harmless one, voids the check
    page.locator("#prog-text").type("; edited")
    until(
        lambda: page.locator("#prog-run").is_disabled(),
        "Run disabled by the edit",
        seen(server, page),
    )
    assert "Check again" in page.locator("#prog-result").inner_text()
    answer = check(page, server, page.locator("#prog-text").input_value())
    assert answer.startswith("passes"), answer
    assert page.locator("#prog-run").is_enabled()


def test_an_unreadable_program_names_its_line_and_word(page: Any, server: Server) -> None:
    known_state(page, server)
    answer = check(page, server, "G21 G90\nG0 X0 Y0 Z-240\nG1 F600 X5 Q7\nM2\n")
    assert answer.startswith("cannot be read"), answer
    assert "line 3" in answer and "Q7" in answer
    assert marked_line(page) == "3"
    assert page.locator("#prog-run").is_disabled()
    drawn = lambda: page.locator("#ws-top").get_attribute("data-program-points")  # noqa: E731
    until(lambda: drawn() == "0", "no program drawn in 2D", drawn)


def test_the_running_line_is_highlighted_and_abort_sent(page: Any, server: Server) -> None:
    """GET /api/runs answered here with a program run on line 4 (the server's runs of
    programs are another branch's): the panel follows it, and Abort posts its abort."""
    known_state(page, server)
    page.fill("#prog-text", (EXAMPLES / "circle.ngc").read_text())
    run = {
        "run_id": "20261201-000000-prog",
        "kind": "program",
        "state": "running",
        "description": "program",
        "progress": {"program_line": 4},
        "params": {},
        "stats": None,
        "has_report": False,
        "reason": None,
    }
    aborted: list[str] = []

    def runs(route: Any) -> None:
        route.fulfill(content_type="application/json", body=json.dumps([run]))

    def abort(route: Any) -> None:
        aborted.append(route.request.url)
        route.fulfill(content_type="application/json", body=json.dumps({"run_id": run["run_id"]}))

    page.route("**/api/runs", runs)
    page.route(f"**/api/runs/{run['run_id']}/abort", abort)
    try:
        running = lambda: page.locator("#prog-text").get_attribute("data-running-line")  # noqa: E731
        until(lambda: running() == "4", "line 4 highlighted", running)
        assert page.locator("#prog-running").is_visible()
        assert page.locator("#prog-gutter span[data-line='4']").get_attribute("class") == "running"
        assert page.locator("#prog-run").is_disabled()
        click_until(page, "#prog-abort", lambda: aborted, "the abort posted", seen(server, page))
        run["state"] = "aborted"
        until(lambda: running() == "", "the highlight gone with the run", seen(server, page))
        assert "aborted" in page.locator("#prog-state").inner_text()
    finally:
        page.unroute("**/api/runs", runs)
        page.unroute(f"**/api/runs/{run['run_id']}/abort", abort)


def test_space_types_in_the_program_and_esc_still_estops(page: Any, server: Server) -> None:
    known_state(page, server)
    page.fill("#prog-text", "G0 X0")
    stops = page.evaluate("window.deltadash.estops.length")
    box = page.locator("#prog-text")
    box.press("End")
    box.press("Space")
    box.type("Y0")
    # the keys went through the page's e-stop handler (capture, first) before the text
    until(lambda: box.input_value() == "G0 X0 Y0", "the space typed", box.input_value)
    assert page.evaluate("window.deltadash.estops.length") == stops
    assert not status(server)["estopped"]

    box.press("Escape")
    until(lambda: status(server)["estopped"], "the e-stop by Esc", seen(server, page))
    assert page.evaluate("window.deltadash.estops.length") == stops + 1
    click_until(page, "#reset", lambda: not status(server)["estopped"], "reset", seen(server, page))


def test_run_sends_the_checked_text_and_shows_a_refusal_by_line(page: Any, server: Server) -> None:
    """POST /api/programs/run answered here (its server side is another branch): the body
    is the checked text and the feed-forward choice; a 422 with violations shows them."""
    known_state(page, server)
    text = (EXAMPLES / "circle.ngc").read_text()
    page.fill("#prog-text", "")
    page.set_input_files("#prog-file", str(EXAMPLES / "circle.ngc"))  # opened as a file
    box = page.locator("#prog-text")
    until(lambda: box.input_value() == text, "the file in the text box", box.input_value)
    answer = check(page, server, None)
    assert answer.startswith("passes"), answer
    sent: list[dict[str, Any]] = []
    refusal = {
        "detail": "the program fails its check from where the robot is",
        "violations": [
            {
                "line": 4,
                "kind": "ik",
                "message": "no joint solution",
                "t_s": 1.5,
                "point_m": [0.02, 0.0, -0.24],
            },
        ],
    }

    def run(route: Any) -> None:
        sent.append(json.loads(route.request.post_data))
        if len(sent) == 1:
            route.fulfill(
                status=200,
                content_type="application/json",
                body=json.dumps({"run_id": "20261201-000001-prog"}),
            )
        else:
            route.fulfill(status=422, content_type="application/json", body=json.dumps(refusal))

    page.route("**/api/programs/run", run)
    try:
        page.check("#prog-ff", timeout=PAGE_WAIT_S * 1e3)
        click_until(page, "#prog-run", lambda: sent, "the run posted", seen(server, page))
        # the checked text, the feed-forward choice, the work offset it was checked with
        # (the config's: 0; the file states none) and its name for the library (the file's)
        assert (sent[0]["gcode"], sent[0]["feedforward"]) == (text, True)
        assert (sent[0]["work_offset_m"], sent[0]["name"]) == ([0, 0, 0], "circle.ngc")
        state = page.locator("#prog-state")
        until(
            lambda: "20261201-000001-prog" in state.inner_text(),
            "the run named",
            seen(server, page),
        )

        click_until(
            page, "#prog-run", lambda: len(sent) > 1, "the second run posted", seen(server, page)
        )
        result = page.locator("#prog-result")
        until(
            lambda: result.inner_text().startswith("not started"), "the refusal", seen(server, page)
        )
        lines = page.locator("#prog-violation-rows tr").evaluate_all(
            "rs => rs.map(r => r.dataset.line)"
        )
        assert lines == ["4"]
        assert page.locator("#prog-run").is_disabled()  # a refused run needs a new check
    finally:
        page.unroute("**/api/programs/run", run)

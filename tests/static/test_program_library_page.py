"""The program panel's work offset, file name, library and dry run (issue 32), in Debian's
chromium against `deltadash serve`.

Laws, not echoes: every examples/*.ngc opened as a file and checked from the page as
shipped gives the report the API gives for the same text and offset (and the CLI's verdict:
the three that pass with their stated offset pass); the file name shows exactly while the
text is the file's; a program sent comes back from the library as it was sent, and the
page's list is the server's; the dry run's table is the API's answer for the same body, its
worst line the one with the largest predicted error.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.static.test_programs_page import (
    at_the_middle,
    check,
    click_until,
    known_state,
    seen,
    until,
)
from tests.support.browser import (
    PAGE_WAIT_S,
    browser_skip_reason,
    dashboard_page,
    save_artifact,
)
from tests.support.server import Server

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
# the CLI's verdicts (tests/app/cli/test_gcode.py), each with the offset its header states
PASSES = {"circle.ngc": True, "helix.ngc": True, "pick_and_place.ngc": True, "fails.ngc": False}
STATED_MM = {"pick_and_place.ngc": [0.0, 0.0, -280.0]}  # its line 2: "G54 at 0, 0, -0.28 m"


@pytest.fixture(scope="module")
def sent() -> dict[str, list[dict[str, Any]]]:
    """The bodies the page posts to the programs routes, by route's last part."""
    return {}


@pytest.fixture(scope="module")
def page(server: Server, sent: dict[str, list[dict[str, Any]]]) -> Iterator[Any]:
    def listen(page: Any) -> None:
        def record(request: Any) -> None:
            if request.method == "POST" and "/api/programs/" in request.url:
                part = request.url.rsplit("/", 1)[1]
                sent.setdefault(part, []).append(json.loads(request.post_data or "{}"))

        page.on("request", record)

    with dashboard_page(server, on_page=listen) as page:
        yield page


def post(server: Server, path: str, body: dict[str, Any]) -> dict[str, Any]:
    return server.post(path, body)


def offset_mm(page: Any) -> list[float]:
    return [float(page.input_value(f"#prog-off-{a}").replace(",", ".")) for a in "xyz"]


def open_file(page: Any, name: str) -> str:
    text = (EXAMPLES / name).read_text()
    page.set_input_files("#prog-file", str(EXAMPLES / name))
    box = page.locator("#prog-text")
    until(lambda: box.input_value() == text, f"{name} in the text box", box.input_value)
    return text


@pytest.mark.parametrize("name", sorted(PASSES))
def test_every_example_checks_from_the_page_as_the_api_does(
    page: Any, server: Server, sent: dict[str, list[dict[str, Any]]], name: str
) -> None:
    known_state(page, server)
    text = open_file(page, name)
    assert page.locator("#prog-file-name").inner_text() == name
    # the offset the file states (pick_and_place's header), else the config's (0, 0, 0)
    assert offset_mm(page) == STATED_MM.get(name, [0.0, 0.0, 0.0])
    note = page.locator("#prog-off-note").inner_text()
    assert ("line 2" in note) if name in STATED_MM else ("configuration" in note), note
    before = len(sent.get("check", []))
    answer = check(page, server, None)
    body = sent["check"][before]
    assert body["gcode"] == text and body["name"] == name
    assert body["work_offset_m"] == pytest.approx([v / 1000 for v in offset_mm(page)])
    # the API's check of the same text and offset, from the same held point
    api = post(server, "/api/programs/check", {k: body[k] for k in ("gcode", "work_offset_m")})
    assert api["ok"] is PASSES[name], api["violations"][:3]
    assert answer.startswith("passes" if api["ok"] else "fails"), answer
    if api["ok"]:
        assert f"{api['duration_s']:.2f} s" in answer
        assert f"path {api['length_m'] * 1000:.1f} mm" in answer
    else:
        n = len(api["violations"])
        assert answer.startswith(f"fails: {n} violation"), answer
        rows = page.locator("#prog-violation-rows tr").evaluate_all(
            "rs => rs.map(r => [Number(r.dataset.line), r.cells[1].textContent])"
        )
        assert rows == [[v["line"], v["kind"]] for v in api["violations"]]
    figures = page.locator("#prog-figures").inner_text()
    shown = ", ".join(f"{v * 1000:g}" for v in api["work_offset_m"])
    assert f"({shown}) mm" in figures, figures
    assert page.locator("#prog-run").is_enabled() is api["ok"]


def test_pick_and_place_without_its_offset_fails_and_the_page_offers_it(
    page: Any, server: Server
) -> None:
    known_state(page, server)
    open_file(page, "pick_and_place.ngc")
    for axis in "xyz":
        page.fill(f"#prog-off-{axis}", "0")
    offer = page.locator("#prog-off-use")
    until(offer.is_visible, "the offer of the stated offset", offer.inner_text)
    assert "(0, 0, -280) mm" in offer.inner_text()
    answer = check(page, server, None)
    assert answer.startswith("fails"), answer  # z = 5..40 mm above the base
    offer.click()
    until(
        lambda: offset_mm(page) == [0.0, 0.0, -280.0], "the offset taken", lambda: offset_mm(page)
    )
    assert offer.is_hidden()
    assert "changed since the check" in page.locator("#prog-result").inner_text()
    assert check(page, server, None).startswith("passes")


def test_a_bad_offset_is_said_and_nothing_is_sent(
    page: Any, server: Server, sent: dict[str, list[dict[str, Any]]]
) -> None:
    known_state(page, server)
    page.fill("#prog-text", "G4 P0.1\nM2\n")
    page.fill("#prog-off-y", "1,2,3")
    before = len(sent.get("check", []))
    answer = check(page, server, None)
    assert answer.startswith("not checked: work offset Y"), answer
    assert "not a number" in answer
    assert len(sent.get("check", [])) == before
    page.fill("#prog-off-y", "0")


def test_the_file_name_shows_only_while_the_text_is_the_files(page: Any, server: Server) -> None:
    text = open_file(page, "circle.ngc")
    label = page.locator("#prog-file-name")
    assert label.inner_text() == "circle.ngc"
    page.fill("#prog-text", "G21 G90\nG0 X0 Y0 Z-230\nM2\n")  # other text pasted
    until(lambda: label.inner_text() == "edited, unsaved", "the label", label.inner_text)
    page.locator("#prog-text").fill(text)  # the file's text again: its name again
    until(lambda: label.inner_text() == "circle.ngc", "the name back", label.inner_text)
    page.locator("#prog-text").press("End")
    page.locator("#prog-text").type(" ")
    until(lambda: "circle.ngc" not in label.inner_text(), "the typed edit", label.inner_text)
    page.fill("#prog-text", "")
    until(lambda: label.inner_text() == "", "no label for no text", label.inner_text)


def test_a_program_sent_comes_back_from_the_library_as_sent(
    page: Any, server: Server, sent: dict[str, list[dict[str, Any]]]
) -> None:
    known_state(page, server)
    text = open_file(page, "pick_and_place.ngc")
    check(page, server, None)
    edited = text + "(an edit)\n"
    page.fill("#prog-text", edited)
    for axis, value in zip("xyz", ("1", "2", "-281"), strict=True):
        page.fill(f"#prog-off-{axis}", value)
    before = len(sent.get("check", []))
    check(page, server, None)
    assert sent["check"][before]["name"] == "pick_and_place.ngc (edited)"
    listed = server.get("/api/programs/library")["programs"]
    select = page.locator("#prog-library")
    ids = "s => [...s.options].map(o => o.value).filter(Boolean)"
    until(
        lambda: (
            select.evaluate(ids)
            == [e["id"] for e in server.get("/api/programs/library")["programs"]]
        ),
        "the page's list as the server's",
        lambda: (select.evaluate(ids), listed),
    )
    first = server.get("/api/programs/library")["programs"][0]
    assert first["name"] == "pick_and_place.ngc (edited)" and first["lines"] == len(
        edited.splitlines()
    )
    # the unedited file, reopened: its text, its name, the offset its header states
    page.fill("#prog-text", "")
    original = next(
        e
        for e in server.get("/api/programs/library")["programs"]
        if e["name"] == "pick_and_place.ngc"
    )
    select.select_option(original["id"])
    click_until(
        page,
        "#prog-library-open",
        lambda: page.locator("#prog-text").input_value() == text,
        "the kept program opened",
        seen(server, page),
    )
    assert page.locator("#prog-file-name").inner_text() == "pick_and_place.ngc"
    assert offset_mm(page) == [0.0, 0.0, -280.0]
    # the edited one: its text, and the offset it was sent with (it states -280 too: the
    # header wins, as for a file; the one sent is in the list's entry)
    select.select_option(first["id"])
    click_until(
        page,
        "#prog-library-open",
        lambda: page.locator("#prog-text").input_value() == edited,
        "the edited program opened",
        seen(server, page),
    )
    assert first["work_offset_m"] == pytest.approx([0.001, 0.002, -0.281])
    assert page.locator("#prog-file-name").inner_text() == "pick_and_place.ngc (edited)"
    # a file opened after it: the list's choice and its note go (the text is the file's)
    open_file(page, "circle.ngc")
    assert select.input_value() == ""
    assert page.locator("#prog-library-note").inner_text() == ""


def test_the_dry_run_shows_the_apis_error_per_line_and_marks_the_worst(
    page: Any, server: Server, sent: dict[str, list[dict[str, Any]]]
) -> None:
    known_state(page, server)
    text = open_file(page, "circle.ngc")
    held: list[Any] = []

    def hold(route: Any) -> None:  # the first one held: the page shows it is running
        held.append(route)

    page.route("**/api/programs/dry-run", hold)
    result = page.locator("#prog-dry-result")
    answers = int(result.get_attribute("data-answers") or 0)
    try:
        click_until(page, "#prog-dry", lambda: held, "the dry run sent", seen(server, page))
        progress = page.locator("#prog-dry-progress")
        until(progress.is_visible, "the dry run's progress", result.inner_text)
        assert "playing the program on the twin" in result.inner_text()
        assert page.locator("#prog-dry").is_disabled()
    finally:
        page.unroute("**/api/programs/dry-run", hold)
    held[0].continue_()
    until(
        lambda: int(result.get_attribute("data-answers") or 0) > answers,
        "the dry run's answer",
        result.inner_text,
    )
    assert page.locator("#prog-dry-progress").is_hidden()
    body = sent["dry-run"][-1]
    assert body["gcode"] == text and body["work_offset_m"] == [0, 0, 0]
    api = post(server, "/api/programs/dry-run", {k: body[k] for k in ("gcode", "work_offset_m")})
    rows = page.locator("#prog-dry-rows tr").evaluate_all(
        "rs => rs.map(r => [...r.cells].map(c => c.textContent))"
    )
    assert [int(r[0]) for r in rows] == [e["line"] for e in api["lines"]]
    for row, e in zip(rows, api["lines"], strict=True):
        # the same twin from the same held point: the page's figures are the API's (mm, 3
        # decimals; a last-digit rounding allowed for the held point's float noise)
        assert float(row[1]) == pytest.approx(e["rmse_m"] * 1000, abs=2e-3)
        assert float(row[2]) == pytest.approx(e["max_m"] * 1000, abs=2e-3)
        assert int(row[3]) == e["samples"]
        assert row[4] == text.split("\n")[e["line"] - 1].strip()[:60]
    worst = max(api["lines"], key=lambda e: e["max_m"])["line"]
    box = page.locator("#prog-text")
    assert box.get_attribute("data-worst-line") == str(worst)
    assert "worst" in (
        page.locator(f"#prog-gutter span[data-line='{worst}']").get_attribute("class") or ""
    )
    assert page.locator("#prog-dry-rows tr.worst").get_attribute("data-line") == str(worst)
    assert f"worst on line {worst}" in result.inner_text()
    shot = page.locator(".programs").screenshot(timeout=PAGE_WAIT_S * 1e3)
    save_artifact("dashboard-program-dry-run.png", shot)
    # an edit voids it: the mark goes
    box.press("End")
    box.type(" ")
    until(lambda: box.get_attribute("data-worst-line") == "", "the mark gone", result.inner_text)
    assert "changed since the dry run" in result.inner_text()


def test_a_dry_run_refused_says_why(page: Any, server: Server) -> None:
    known_state(page, server)
    page.fill("#prog-text", "G21\nG4 P100\nM2\n")  # longer than programs.dry_run_max_s (60 s)
    result = page.locator("#prog-dry-result")
    answers = int(result.get_attribute("data-answers") or 0)
    click_until(
        page,
        "#prog-dry",
        lambda: int(result.get_attribute("data-answers") or 0) > answers,
        "the refusal",
        seen(server, page),
    )
    said = result.inner_text()
    assert said.startswith("dry run refused: the program lasts 100.0 s"), said
    assert "gcode:" not in said
    assert page.locator("#prog-dry-table").is_hidden()
    page.fill("#prog-text", "G21\nG1 F100 X1 Q7\n")
    answers = int(result.get_attribute("data-answers") or 0)
    click_until(
        page,
        "#prog-dry",
        lambda: int(result.get_attribute("data-answers") or 0) > answers,
        "the unreadable one",
        seen(server, page),
    )
    assert result.inner_text().startswith("dry run: cannot be read (line 2"), result.inner_text()
    assert page.locator("#prog-text").get_attribute("data-marked-line") == "2"


def test_pick_and_place_runs_from_the_page_as_shipped(page: Any, server: Server) -> None:
    """Opened as a file, checked and run with the offset its header states: the run
    starts, ends done, and its record has that offset (the robot back over the middle)."""
    known_state(page, server)
    text = open_file(page, "pick_and_place.ngc")
    assert offset_mm(page) == [0.0, 0.0, -280.0]
    assert check(page, server, None).startswith("passes")
    before = {r["run_id"] for r in server.get("/api/runs")}

    def started() -> dict[str, Any] | None:
        runs = [r for r in server.get("/api/runs") if r["run_id"] not in before]
        return next((r for r in runs if r["kind"] == "program"), None)

    run = click_until(page, "#prog-run", started, "the program run started", seen(server, page))
    done = until(
        lambda: (r := server.get(f"/api/runs/{run['run_id']}"))["state"] != "running" and r,
        "the program run's end",
        seen(server, page),
    )
    assert done["state"] == "done", done.get("reason")
    assert done["params"]["gcode"] == text
    assert done["params"]["work_offset_m"] == pytest.approx([0.0, 0.0, -0.28])
    until(lambda: at_the_middle(server), "back over the middle (X0 Y0 Z40)", seen(server, page))

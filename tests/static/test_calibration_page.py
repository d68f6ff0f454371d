"""The calibration panel in Debian's chromium against `deltadash serve` on the twin built
wrong on purpose (joint offsets of 2.9, -1.7 and 1.1 deg), walked as the lab's engineer
would: bad parameters refused in the page's words with nothing sent, a run started and
aborted mid-way (the arm holds, the run ends aborted on the server), then a 12-pose run
from start to finish (the steps marked, the progress bar moving), its report's figures
matched against GET /api/calibration/{id}, its residuals image shown, and the apply: the
confirmation says the offsets, the POST names that run, and the server then uses the
offsets the page said, which are the twin's own within a few tenths of a degree.

What was sent is read from the requests the page made; a request that must not be sent is
checked by making a harmless one after it and waiting for that."""

from __future__ import annotations

import json
import math
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
    save_artifact,
    toasts,
)
from tests.support.server import Server, serve, wait_for

SKIP = browser_skip_reason()
UNSTICK_HEADER = ".bar { position: static !important; }"  # over the section's top otherwise
pytestmark = [
    pytest.mark.browser,
    pytest.mark.slow,  # calibration runs on the twin: minutes on a loaded 2-core machine
    pytest.mark.skipif(SKIP is not None, reason=str(SKIP)),
]
TRUE_OFFSETS_RAD = (0.05, -0.03, 0.02)
RUN_S = 600.0  # a bound on a 12-pose run on a loaded machine; not a timing assertion


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[Server]:
    env = {
        **PATIENT_SIM_ENV,
        "DELTADASH_HARDWARE__SIM__TRUE_JOINT_OFFSETS_RAD": json.dumps(list(TRUE_OFFSETS_RAD)),
    }
    with serve(tmp_path_factory.mktemp("calibration-page"), **env) as served:
        yield served


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    def listen(page: Any) -> None:
        page.sent = []  # (method, path, body) of every request to the panel's routes
        page.on("request", lambda r: record(page, r))

    with dashboard_page(server, on_page=listen) as page:
        yield page


def record(page: Any, request: Any) -> None:
    url = urlparse(request.url)
    if url.path.startswith(("/api/calibration", "/api/mav/pose")):
        body = json.loads(request.post_data) if request.post_data else None
        page.sent.append((request.method, url.path, body))


def sent(page: Any, method: str, path: str) -> list[Any]:
    page.evaluate("0")  # Playwright delivers the page's events during a call into it
    return [body for m, p, body in page.sent if m == method and p == path]


def text(page: Any, selector: str) -> str:
    return page.locator(selector).inner_text()


def torque_on(page: Any, server: Server) -> None:
    clicked = [-1e9]

    def on() -> bool:
        if server.get("/api/status")["torque"]:
            return True
        if time.monotonic() - clicked[0] > 2.0:  # the twin's arm may still swing at start
            clicked[0] = time.monotonic()
            page.click("#torque-on")
        return False

    waiting.wait_for(on, "torque on", PAGE_WAIT_S, poll_s=0.2, seen=server.brief)


def page_run(page: Any) -> dict | None:
    return page.evaluate("window.deltadash.calibration.run()")


def mm2(m: float) -> str:
    return f"{m * 1e3:.2f} mm"


def test_bad_parameters_are_refused_in_the_pages_words_and_nothing_is_sent(
    page: Any, server: Server
) -> None:
    torque_on(page, server)  # so that the server's refusal below is the stream's
    page.locator("#cal-h").scroll_into_view_if_needed()
    wait_for(
        lambda: page.evaluate("Boolean(window.deltadash && window.deltadash.calibration)"),
        "the panel",
    )
    refusals = [
        ("poses", "5", "Not started: poses: 5 is outside 12 to 300"),
        ("poses", "12,5", 'Not started: poses: "12,5" is not a whole number (12 to 300)'),
        ("poses", "", "Not started: poses: is empty (12 to 300)"),
    ]
    for field, typed, words in refusals:
        page.fill(f"#cal-form input[name={field}]", typed)
        page.click("#cal-start")
        wait_for(lambda w=words: text(page, "#cal-message") == w, f"the refusal of {typed!r}")
        assert page.get_attribute(f"#cal-form input[name={field}]", "aria-invalid") == "true"
    assert words in toasts(page)
    page.fill("#cal-form input[name=poses]", "12")
    page.select_option("#cal-form select[name=source]", "probe")
    assert "simulated robot has a probe" in text(page, "#cal-source-needs")
    page.fill("#cal-form input[name=plate]", "+10")
    page.click("#cal-start")
    words = "Not started: plate height: 10 mm is not below the base (between -2000 and 0 mm, z up)"
    wait_for(lambda: text(page, "#cal-message") == words, "the refusal of a plate above the base")
    # a harmless request after the refused ones: the motion-capture stream's state
    page.select_option("#cal-form select[name=source]", "pose-input")
    wait_for(lambda: sent(page, "GET", "/api/mav/pose"), "the stream's state asked")
    wait_for(
        lambda: "platform stream: none" in text(page, "#cal-stream"), "the stream's state shown"
    )
    assert "marker on the platform" in text(page, "#cal-source-needs")
    assert sent(page, "POST", "/api/calibration/run") == []
    # the stream has nothing: the server refuses, said in the page's words
    page.click("#cal-start")
    wait_for(lambda: "no fresh motion capture" in text(page, "#cal-message").lower(), "the refusal")
    assert "/api/" not in text(page, "#cal-message") and "body=" not in text(page, "#cal-message")
    assert len(sent(page, "POST", "/api/calibration/run")) == 1
    page.select_option("#cal-form select[name=source]", "external")


def test_a_run_aborted_mid_way_ends_aborted_and_the_arm_holds(page: Any, server: Server) -> None:
    torque_on(page, server)
    page.fill("#cal-form input[name=poses]", "12")
    page.click("#cal-start")
    run = wait_for(
        lambda: (
            (r := page_run(page)) and r["state"] == "moving" and r["progress"]["pose"] >= 1 and r
        ),
        "the run moving, one pose measured",
        PAGE_WAIT_S,
        seen=lambda: (text(page, "#cal-message"), toasts(page)),
    )
    assert page.get_attribute("#cal-steps li:nth-child(2)", "aria-current") == "step"
    assert page.evaluate("document.getElementById('cal-progress').value") > 0
    page.click("#cal-abort")
    wait_for(
        lambda: server.get(f"/api/calibration/{run['run_id']}")["state"] == "aborted",
        "the run aborted on the server",
    )
    assert sent(page, "POST", f"/api/calibration/{run['run_id']}/abort") == [None]
    wait_for(
        lambda: "aborted by the operator" in text(page, "#cal-verdict").lower(),
        "the page says aborted",
    )
    status = server.get("/api/status")
    assert status["torque"] and not status["estopped"] and not status["faults"]
    assert page.locator("#cal-start").is_enabled() and page.locator("#cal-abort").is_disabled()


def test_a_run_from_start_to_apply_on_the_twin(page: Any, server: Server) -> None:
    torque_on(page, server)
    page.fill("#cal-form input[name=poses]", "12")
    page.select_option("#cal-form select[name=parameters]", "offsets")
    starts = len(sent(page, "POST", "/api/calibration/run"))
    before = (page_run(page) or {}).get("run_id")  # the aborted run, still shown
    page.click("#cal-start")
    wait_for(lambda: len(sent(page, "POST", "/api/calibration/run")) > starts, "the start sent")
    assert sent(page, "POST", "/api/calibration/run")[-1] == {
        "poses": 12,
        "parameters": "offsets",
        "source": "motion",
        "measurement": "external",
    }
    seen_states: set[str] = set()

    def ended() -> dict | None:
        r = page_run(page)
        if r and r["run_id"] != before:  # the new run, not the one shown before the start
            seen_states.add(r["state"])
        return (
            r
            if r and r["run_id"] != before and r["state"] in ("done", "refused", "failed")
            else None
        )

    body = wait_for(
        ended,
        "the calibration to end on the page",
        RUN_S,
        seen=lambda: (page_run(page) or {}).get("progress"),
    )
    assert body["state"] == "done", body
    assert "moving" in seen_states
    run_id = body["run_id"]
    api = server.get(f"/api/calibration/{run_id}")
    # the steps: all four done, the progress bar full
    wait_for(lambda: page.locator("#cal-steps li.done").count() == 4, "every step marked done")
    assert page.evaluate("document.getElementById('cal-progress').value") == 1
    assert text(page, "#cal-progress-text") == f"{run_id}: done, pose 12 of 12"
    # the figures shown are the API's
    wait_for(lambda: page.get_attribute("#cal-figures", "data-run") == run_id, "the report")
    assert f"Calibration {run_id} done: see its report below" in toasts(page)
    assert text(page, "#cal-r-rmse") == f"{mm2(api['rmse_before_m'])} → {mm2(api['rmse_after_m'])}"
    assert text(page, "#cal-r-holdout") == (
        f"{mm2(api['holdout_rmse_before_m'])} → {mm2(api['holdout_rmse_m'])}"
    )
    assert text(page, "#cal-r-condition") == f"{api['condition_number']:.1f}"
    held = api["holdout_poses"]
    assert text(page, "#cal-r-poses") == f"{12 - held} fitted, {held} held out"
    assert text(page, "#cal-r-unobservable").startswith("none")
    shown = [float(v.rstrip("°")) for v in text(page, "#cal-r-offsets").split(", ")]
    found = api["parameters"]["joint_offsets_rad"]
    assert shown == pytest.approx([math.degrees(o) for o in found], abs=5e-4)
    assert "better than the model in use" in text(page, "#cal-verdict")
    assert api["holdout_rmse_m"] < api["holdout_rmse_before_m"]
    # the residuals' image, served by the API, drawn
    wait_for(
        lambda: page.evaluate(
            "(() => { const i = document.getElementById('cal-report-img');"
            " return !i.hidden && i.complete && i.naturalWidth > 0; })()"
        ),
        "report.png shown",
    )
    page.locator("#cal-h").scroll_into_view_if_needed()
    box = page.locator("section.calibration")
    save_artifact("calibration-panel.png", box.screenshot(style=UNSTICK_HEADER))

    # apply: the confirmation says what changes; the POST names this run; the server then
    # uses the offsets said, which are the twin's own
    page.click("#cal-apply")
    wait_for(lambda: page.locator("#confirm").is_visible(), "the apply's confirmation")
    said = text(page, "#confirm-text")
    assert said.startswith(f"Apply calibration {run_id}?") and "Nothing moves" in said
    offsets = [float(v) for v in re.findall(r"joint \d ([+-]\d+\.\d+)°", said)]
    assert offsets == pytest.approx([math.degrees(o) for o in found], abs=5e-4)
    assert offsets == pytest.approx([math.degrees(o) for o in TRUE_OFFSETS_RAD], abs=0.3)
    assert sent(page, "POST", f"/api/calibration/{run_id}/apply") == []  # not before the yes
    page.click("#confirm-yes")
    wait_for(lambda: server.get(f"/api/calibration/{run_id}")["state"] == "applied", "the apply")
    assert sent(page, "POST", f"/api/calibration/{run_id}/apply") == [None]
    applied = wait_for(
        lambda: page.evaluate("window.deltadash.calibration.applied || null"), "the apply's answer"
    )
    assert [math.degrees(o) for o in applied["joint_offsets_rad"]] == pytest.approx(
        offsets, abs=5e-4
    )
    wait_for(lambda: "applied: the controller uses it" in text(page, "#cal-verdict"), "applied")
    assert page.locator("#cal-apply").is_disabled()

"""The tuning panel in Debian's chromium against `deltadash serve` on the twin, walked as
the lab's engineer would: bad targets refused in the page's words with nothing sent (the
revert, harmless with nothing applied, refused in words after them), a run aborted mid-way
(the arm holds, the run ends aborted on the server), then a run of joint 1 from start to
finish (the steps marked, the progress bar full), its report matched against GET
/api/tuning/{id} (the fitted model, the twin check's candidates and figures, the chosen
one), the Bode figure shown, the apply (the confirmation says which servo gets which gains
and what they miss; the servo then holds the gains said) and the revert (the factory gains
back).

What was sent is read from the requests the page made; a request that must not be sent is
checked by making a harmless one after it and waiting for that."""

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
    save_artifact,
    toasts,
)
from tests.support.server import Server, serve, wait_for

SKIP = browser_skip_reason()
UNSTICK_HEADER = ".bar { position: static !important; }"  # over the section's top otherwise
pytestmark = [
    pytest.mark.browser,
    pytest.mark.slow,  # tuning runs on the twin and its check: minutes on a loaded machine
    pytest.mark.skipif(SKIP is not None, reason=str(SKIP)),
]
FACTORY = {"p": 800, "i": 0, "d": 0, "ff1": 0, "ff2": 0}
LIMIT_WORDS = {  # tuning.js's names of the twin check's limits
    "rmse_xy_m": "tracking error x, y",
    "rmse_z_m": "tracking error z",
    "at_limit": "PWM at its limit",
    "overshoot_pct": "step overshoot",
    "rest_m": "error at rest",
    "long_overshoot_m": "overshoot after a long move",
    "settle_band_m": "settling band",
    "settle_s": "settling time after a long move",
}
DEFAULTS = {"bandwidth_hz": "20", "phase_margin_deg": "60", "overshoot_pct": "5"}
RUN_S = 900.0  # a bound on a run and its twin check on a loaded machine; not a timing assertion


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[Server]:
    with serve(tmp_path_factory.mktemp("tuning-page"), **PATIENT_SIM_ENV) as served:
        yield served


@pytest.fixture(scope="module")
def page(server: Server) -> Iterator[Any]:
    def listen(page: Any) -> None:
        page.sent = []  # (method, path, body) of every request to the panel's routes
        page.on("request", lambda r: record(page, r))

    with dashboard_page(server, on_page=listen) as page:
        yield page


def record(page: Any, request: Any) -> None:
    path = urlparse(request.url).path
    if path.startswith("/api/tuning"):
        body = json.loads(request.post_data) if request.post_data else None
        page.sent.append((request.method, path, body))


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
    return page.evaluate("window.deltadash.tuning.run()")


def only_joint_1(page: Any) -> None:
    page.check("#tun-form input[name=joint1]")
    page.uncheck("#tun-form input[name=joint2]")
    page.uncheck("#tun-form input[name=joint3]")


def mm2(m: float) -> str:
    return f"{m * 1e3:.2f}"


def gains_text(g: dict) -> str:
    ff = f", FF1 {g['ff1']}, FF2 {g['ff2']}" if g["ff1"] or g["ff2"] else ""
    return f"P {g['p']}, I {g['i']}, D {g['d']}{ff}"


def test_bad_targets_are_refused_in_the_pages_words_and_nothing_is_sent(page: Any) -> None:
    page.locator("#tun-h").scroll_into_view_if_needed()
    wait_for(lambda: page.evaluate("Boolean(window.deltadash && window.deltadash.tuning)"), "panel")
    refusals = [
        ("bandwidth_hz", "0", "Not started: bandwidth: 0 Hz is outside 0.1 to 100 Hz"),
        ("bandwidth_hz", "2O", 'Not started: bandwidth: "2O" is not a number (e.g. 12.5 or 12,5)'),
        ("phase_margin_deg", "90", "Not started: phase margin: 90 ° is outside 20 to 85 °"),
        ("overshoot_pct", "0", "Not started: overshoot: 0 % is outside above 0 and at most 50 %"),
    ]
    for field, typed, words in refusals:
        page.fill(f"#tun-form input[name={field}]", typed)
        page.click("#tun-start")
        wait_for(lambda w=words: text(page, "#tun-message") == w, f"the refusal of {typed!r}")
        assert page.get_attribute(f"#tun-form input[name={field}]", "aria-invalid") == "true"
        page.fill(f"#tun-form input[name={field}]", DEFAULTS[field])
    assert words in toasts(page)
    for j in (1, 2, 3):
        page.uncheck(f"#tun-form input[name=joint{j}]")
    page.click("#tun-start")
    words = "Not started: joints: choose at least one joint"
    wait_for(lambda: text(page, "#tun-message") == words, "the refusal of no joint")
    # a harmless request after the refused ones: a revert with nothing applied, refused
    page.click("#tun-revert")
    wait_for(lambda: page.locator("#confirm").is_visible(), "the revert's confirmation")
    page.click("#confirm-yes")
    wait_for(lambda: sent(page, "POST", "/api/tuning/revert"), "the revert sent")
    wait_for(lambda: "Nothing to revert" in text(page, "#tun-message"), "the revert refused")
    assert "/api/" not in text(page, "#tun-message")
    assert sent(page, "POST", "/api/tuning/run") == []


def test_a_run_aborted_mid_way_ends_aborted_and_the_arm_holds(page: Any, server: Server) -> None:
    torque_on(page, server)
    only_joint_1(page)
    page.click("#tun-start")
    run = wait_for(
        lambda: (r := page_run(page)) and r["state"] in ("step", "chirp") and r,
        "the run recording its step or chirp",
        PAGE_WAIT_S,
        seen=lambda: (text(page, "#tun-message"), toasts(page), server.brief()),
    )
    at = 3 if run["state"] == "step" else 4
    assert page.get_attribute(f"#tun-steps li:nth-child({at})", "aria-current") == "step"
    page.click("#tun-abort")
    wait_for(
        lambda: server.get(f"/api/tuning/{run['run_id']}")["state"] == "aborted",
        "the run aborted on the server",
    )
    assert sent(page, "POST", f"/api/tuning/{run['run_id']}/abort") == [None]
    wait_for(
        lambda: "aborted by the operator" in text(page, "#tun-verdict").lower(), "the page says so"
    )
    status = server.get("/api/status")
    assert status["torque"] and not status["estopped"] and not status["faults"]
    assert page.locator("#tun-start").is_enabled() and page.locator("#tun-abort").is_disabled()


def test_a_run_from_start_to_apply_and_revert_on_the_twin(page: Any, server: Server) -> None:
    torque_on(page, server)
    only_joint_1(page)
    starts = len(sent(page, "POST", "/api/tuning/run"))
    before = (page_run(page) or {}).get("run_id")  # the aborted run, still shown
    page.click("#tun-start")
    wait_for(lambda: len(sent(page, "POST", "/api/tuning/run")) > starts, "the start sent")
    assert sent(page, "POST", "/api/tuning/run")[-1] == {
        "joints": [1],
        "target": {
            "bandwidth_hz": 20,
            "phase_margin_deg": 60,
            "overshoot_pct": 5,
            "pwm_fraction": 0.8,
            "feedforward": False,
        },
    }
    seen_states: set[str] = set()

    def ended() -> dict | None:
        r = page_run(page)
        if r and r["run_id"] != before:  # the new run, not the one shown before the start
            seen_states.add(r["state"])
        return (
            r
            if r and r["run_id"] != before and r["state"] in ("done", "failed", "aborted")
            else None
        )

    body = wait_for(
        ended,
        "the tuning to end on the page",
        RUN_S,
        seen=lambda: (page_run(page) or {}).get("state"),
    )
    assert body["state"] == "done", body
    assert {"checking"} <= seen_states, seen_states
    run_id = body["run_id"]
    api = server.get(f"/api/tuning/{run_id}")
    assert server.get("/api/tuning")[0] == {  # the newest run, which a reload follows
        "run_id": run_id,
        "state": "done",
        "joints": [1],
        "met_goal": api["checked"]["met_goal"],
        "error": None,
    }
    wait_for(lambda: page.locator("#tun-steps li.done").count() == 7, "every step marked done")
    assert page.evaluate("document.getElementById('tun-progress').value") == 1
    # the fitted model, as the API gives it
    wait_for(lambda: page.get_attribute("#tun-report", "data-run") == run_id, "the report")
    cells = page.locator("#tun-models tr").first.locator("td").all_inner_texts()
    model = api["model"]["1"]
    assert cells[0] == f"{model['bandwidth_hz']:.1f}" and cells[1] == f"{model['zeta']:.2f}"
    assert cells[2] == f"{model['delay_s'] * 1e3:.1f}"
    # the twin check's candidates, their figures and the chosen one
    checked = api["checked"]
    rows = page.locator("#tun-candidates tr")
    assert rows.count() == len(checked["candidates"])
    for k, candidate in enumerate(checked["candidates"]):
        row = rows.nth(k).locator("td").all_inner_texts()
        assert row[0] == gains_text(candidate["gains"]["1"])  # the servo tuned
        assert row[1] == " / ".join(mm2(v) for v in candidate["plain"]["rmse_m"])
        assert row[2] == " / ".join(mm2(v) for v in candidate["lead"]["rmse_m"])
        at_limit = max(candidate["plain"]["at_limit"], candidate["lead"]["at_limit"])
        assert row[3] == f"{at_limit * 100:.1f}"
        assert row[4] == f"{candidate['overshoot_pct']:.1f}"
        assert row[5] == mm2(max(candidate["rest_m"]))
        long = candidate["long_move"]
        assert row[6] == f"{mm2(max(long['overshoot_m']))} / {max(long['settle_s']):.2f}"
        assert (row[7] == "passes") == candidate["passes"], (row, candidate)
        assert candidate["passes"] or row[7].startswith("misses: ")
    chosen = page.locator("#tun-candidates tr.chosen")
    assert chosen.get_attribute("data-candidate") == str(checked["chosen"])
    reason = checked["reason"]  # the API's sentence, the limits' names said in words
    for name, words in LIMIT_WORDS.items():
        reason = reason.replace(name, words)
    assert text(page, "#tun-reason") == reason
    assert f"Tuning {run_id} done: see its report below" in toasts(page)
    met = "meet the goal on the twin" if checked["met_goal"] else "do NOT meet the goal"
    assert met in text(page, "#tun-verdict")
    wait_for(
        lambda: page.evaluate(
            "(() => { const i = document.getElementById('tun-bode');"
            " return !i.hidden && i.complete && i.naturalWidth > 0; })()"
        ),
        "bode.png shown",
    )
    page.locator("#tun-h").scroll_into_view_if_needed()
    save_artifact(
        "tuning-panel.png", page.locator("section.tuning").screenshot(style=UNSTICK_HEADER)
    )

    # apply: the confirmation names the servo's gains (and what they miss); the servo then
    # holds the gains said
    suggested = api["suggested"]["1"]
    page.click("#tun-apply")
    wait_for(lambda: page.locator("#confirm").is_visible(), "the apply's confirmation")
    said = text(page, "#confirm-text")
    assert f"servo 1: {gains_text(suggested)}." in said, said
    assert ("MISS the goal" in said) == (not checked["met_goal"])
    said_gains = dict(
        zip(
            ("p", "i", "d"),
            map(int, re.search(r"servo 1: P (\d+), I (\d+), D (\d+)", said).groups()),
            strict=True,
        )
    )
    page.click("#confirm-yes")
    wait_for(lambda: server.get("/api/status")["gains"]["1"] != FACTORY, "the gains applied")
    assert server.get("/api/status")["gains"]["1"] == {**suggested, **said_gains}
    assert server.get("/api/status")["gains"]["2"] == FACTORY  # a joint not tuned keeps its
    expected_body = None if checked["met_goal"] else {"confirm_missed": True}
    assert sent(page, "POST", f"/api/tuning/{run_id}/apply") == [expected_body]
    wait_for(lambda: server.get(f"/api/tuning/{run_id}")["state"] == "applied", "applied")

    # revert: the factory gains back
    page.click("#tun-revert")
    wait_for(lambda: page.locator("#confirm").is_visible(), "the revert's confirmation")
    page.click("#confirm-yes")
    wait_for(lambda: server.get("/api/status")["gains"]["1"] == FACTORY, "the revert")
    wait_for(lambda: "reverted: servo 1 P 800" in text(page, "#tun-message"), "said reverted")

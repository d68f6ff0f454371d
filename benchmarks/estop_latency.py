"""The page's e-stop latency: from the key press or click to the server's receipt.

Usage: python benchmarks/estop_latency.py [--trials 20] [--input key|button|both]
       [--no-embed] [--state holding|moving]

`deltadash serve` on the simulator with its 3D scene, and the dashboard in Debian's headless
chromium with software WebGL (SwiftShader), the scene embedded ("show here" ticked: viser
drawing in software) and the plots running. Each trial resets the e-stop (the page's Reset
button), waits a random 0.5 to 1.5 s so that presses fall anywhere in the scene's
frames, then presses Space (or clicks E-STOP) and waits for the server to have it. With
``--state moving`` each press lands during a sinusoid run started from the page (the scene
redrawing the moving arm at its full rate, the plots scrolling): the page's Start run, the
test part under way, then the random wait and the press (which aborts the run). Printed
per input, in ms, p50 / p99 / worst of:

The plots' frame rate over each input's trials is printed beside it (the plots run in their
own frame, plots.html, from the other loopback name: another renderer process than the page).

- page: from the input event's own time stamp in the page (``performance.timeOrigin +
  event.timeStamp``: when chromium received the input, before any wait for the page's main
  thread) to the server's arrival time (GET /api/status ``estop_received_unix_s``);
- request sent -> server: from the page's clock just after its fetch calls returned to
  the arrival (the hop through the browser's network stack, the kernel and the server);
- driver: from just before Playwright sends the input to the same arrival time (includes
  the driver's own delivery of the input to chromium);
- per path (``estop_arrivals_unix_s``, servers since the e-stop listener): from the input
  event to the press's arrival at the listener's thread, at the app's outermost middleware
  (uvicorn has parsed it and the event loop got to it), and at the route's handler (after
  routing and the dependencies). The gaps show where the time goes.

Both clocks are this machine's wall clock. The machine's load is printed too: the figure is
only as good as the CPU it got.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.support.browser import chromium_page, plots_frame  # noqa: E402
from tests.support.server import Server, serve  # noqa: E402


def until(condition: Any, what: str, timeout_s: float = 120.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while not (value := condition()):
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out waiting for {what}")
        time.sleep(0.01)
    return value


def open_page(page: Any, server: Server, embed: bool) -> None:
    """The dashboard with the plots running and the scene embedded and drawing (or not)."""
    page.goto(server.url + "/", wait_until="commit", timeout=300_000)
    until(lambda: page.evaluate("Boolean(window.deltadash)"), "the page's modules")
    until(lambda: page.locator("#conn").inner_text() == "connected", "the page's link")
    if embed:
        page.check("#scene-embed")
        until(
            lambda: any(f != page.main_frame and _canvas(f) for f in page.frames),
            "the embedded scene's canvas",
        )


def _canvas(frame: Any) -> bool:
    try:
        return bool(frame.evaluate("document.querySelectorAll('canvas').length > 0"))
    except Exception:  # the frame navigated or is not ready yet
        return False


PATHS = ("listener", "middleware", "route")


def start_moving(page: Any, server: Server) -> None:
    """A 30 s sinusoid started from the page, waited on until its test part runs (started
    again if a loaded machine faulted it on the way)."""
    page.fill("#run-fields input[name=duration]", "30")
    deadline = time.monotonic() + 300.0
    while True:
        runs = server.get("/api/runs")
        running = [r for r in runs if r["state"] == "running"]
        if running and ((running[0].get("progress") or {}).get("test_elapsed_s") or 0) > 0.2:
            return
        if time.monotonic() > deadline:
            raise TimeoutError(f"no run under way: {page.locator('#toast').inner_text()!r}")
        if not running:  # a click a second until one starts
            status = server.get("/api/status")
            if status["faults"] or status["estopped"]:
                page.click("#reset")
            elif not status["torque"]:
                page.click("#torque-on")
            elif status["ee"]["position_m"][2] < -0.3:  # hanging below the workspace: home
                for axis, value in zip("xyz", ("0", "0", "-240"), strict=True):
                    page.fill(f"#goal-form input[name={axis}]", value)
                page.click("#goal-form button[type=submit]")
                if page.locator("#confirm").is_visible():  # a long move is confirmed
                    page.click("#confirm-yes")
            else:  # below the fold since issue 32's panels: scrolled to, a patient click
                page.locator("#run-start").scroll_into_view_if_needed(timeout=120_000)
                page.click("#run-start", timeout=120_000)
            time.sleep(1.0)
        else:
            time.sleep(0.05)


def trial(
    page: Any, server: Server, how: str, moving: bool = False
) -> tuple[float, float, float, dict[str, float]]:
    """One press: (page event -> server, of which page event -> request sent, driver ->
    server, {path: page event -> arrival by that path}) [ms]."""
    if server.get("/api/status")["estopped"]:
        # as the operator does (the page holds the control lease)
        page.click("#reset", timeout=300_000)
        until(lambda: not server.get("/api/status")["estopped"], "the reset")
    if moving:
        start_moving(page, server)
    before = server.get("/api/status")["estop_received_unix_s"]
    count = page.evaluate("window.deltadash.estops.length")
    time.sleep(random.uniform(0.5, 1.5))
    pressed = time.time()
    if how == "key":
        page.keyboard.press("Space")
    else:  # a press on the button (it stops on press), without Playwright's click checks;
        # where it is now: the header reflows as its texts change
        box = page.locator("#estop").bounding_box(timeout=300_000)
        page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.mouse.down()
        page.mouse.up()
    try:
        received = until(
            lambda: (
                (s := server.get("/api/status"))["estop_received_unix_s"] != before
                and s["estop_received_unix_s"]
            ),
            "the server's e-stop",
        )
    except TimeoutError:  # say what the page saw
        seen = page.evaluate("window.deltadash.estops.slice(-2)")
        focus = page.evaluate("document.activeElement && document.activeElement.id")
        toast = page.locator("#toast").inner_text()
        raise TimeoutError(
            f"no e-stop by {how}: {count} before, {seen}, {focus=}, {toast=}"
        ) from None
    record = until(
        lambda: page.evaluate(f"window.deltadash.estops[{count}]"), "the page's record of the press"
    )
    event_ms = record["event_unix_ms"]
    arrivals: dict[str, float] = {}
    if "estop_arrivals_unix_s" in server.get("/api/status"):
        expected = set(PATHS) if record.get("paths", 1) > 1 else {"middleware", "route"}
        arrivals = until(
            lambda: (
                (a := server.get("/api/status")["estop_arrivals_unix_s"]).keys() >= expected and a
            ),
            "the press's arrival by every path",
        )
    by_path = {path: t * 1e3 - event_ms for path, t in arrivals.items()}
    by_path["sent"] = received * 1e3 - record["sent_unix_ms"]  # the hop: page -> server
    return (
        received * 1e3 - event_ms,
        record["sent_unix_ms"] - event_ms,
        (received - pressed) * 1e3,
        by_path,
    )


def report(name: str, values: list[float]) -> str:
    a = np.asarray(values)
    return (
        f"{name}: p50 {np.percentile(a, 50):.1f}  p99 {np.percentile(a, 99):.1f}  "
        f"worst {a.max():.1f} ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--input", choices=["key", "button", "both"], default="both")
    parser.add_argument("--no-embed", action="store_true", help="the scene not embedded")
    parser.add_argument(
        "--state",
        choices=["holding", "moving"],
        default="holding",
        help="the arm at rest (torque as left) or each press during a sinusoid run",
    )
    args = parser.parse_args()
    inputs = ["key", "button"] if args.input == "both" else [args.input]
    with (
        tempfile.TemporaryDirectory() as folder,
        serve(Path(folder), scene=True) as server,
        chromium_page(1366, 900) as page,
    ):
        open_page(page, server, not args.no_embed)
        print(
            f"scene {'not ' if args.no_embed else ''}embedded, arm {args.state}; "
            f"load {os.getloadavg()}"
        )
        moving = args.state == "moving"
        # the plots' frame (before it, the plots were drawn in the page itself)
        plots = plots_frame(page) if page.locator("#plots-frame").count() else page
        for how in inputs:
            frames, began = plots.evaluate("window.deltadashPlot.frames"), time.monotonic()
            results = [trial(page, server, how, moving) for _ in range(args.trials)]
            fps = (plots.evaluate("window.deltadashPlot.frames") - frames) / (
                time.monotonic() - began
            )
            print(f"{how} ({args.trials} presses; the plots drew {fps:.1f} frames/s meanwhile)")
            print("  " + report("page event -> server", [r[0] for r in results]))
            print("    each press, in order: " + " ".join(f"{r[0]:.0f}" for r in results))
            print("  " + report("  of which event -> request sent", [r[1] for r in results]))
            print("  " + report("driver -> server", [r[2] for r in results]))
            print("  " + report("request sent -> server", [r[3]["sent"] for r in results]))
            for path in PATHS:
                values = [r[3][path] for r in results if path in r[3]]
                if values:
                    print("  " + report(f"page event -> {path}", values))
        print(f"load after {os.getloadavg()}")


if __name__ == "__main__":
    main()

"""The page's e-stop latency: from the key press or click to the server's receipt.

Usage: python benchmarks/estop_latency.py [--trials 20] [--input key|button|both]
       [--no-embed]

`deltadash serve` on the simulator with its 3D scene, and the dashboard in Debian's headless
chromium with software WebGL (SwiftShader), the scene embedded ("show here" ticked: viser
drawing in software) and the plots running. Each trial resets the e-stop (the page's Reset
button), waits a random 0.5 to 1.5 s so that presses fall anywhere in the scene's
frames, then presses Space (or clicks E-STOP) and waits for the server to have it. Printed
per input, in ms, p50 / p99 / worst of:

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

from tests.support.browser import chromium_page  # noqa: E402
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


def trial(page: Any, server: Server, how: str) -> tuple[float, float, float, dict[str, float]]:
    """One press: (page event -> server, of which page event -> request sent, driver ->
    server, {path: page event -> arrival by that path}) [ms]."""
    if server.get("/api/status")["estopped"]:
        # as the operator does (the page holds the control lease)
        page.click("#reset", timeout=300_000)
        until(lambda: not server.get("/api/status")["estopped"], "the reset")
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
    args = parser.parse_args()
    inputs = ["key", "button"] if args.input == "both" else [args.input]
    with (
        tempfile.TemporaryDirectory() as folder,
        serve(Path(folder), scene=True) as server,
        chromium_page(1366, 900) as page,
    ):
        open_page(page, server, not args.no_embed)
        print(f"scene {'not ' if args.no_embed else ''}embedded; load {os.getloadavg()}")
        for how in inputs:
            results = [trial(page, server, how) for _ in range(args.trials)]
            print(f"{how} ({args.trials} presses)")
            print("  " + report("page event -> server", [r[0] for r in results]))
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

"""Shared browser fixtures: Debian's chromium driven by Playwright (no browser download).

``make test`` installs chromium with apt when it is missing (see the Makefile's ``browser``
target); where that was impossible, tests using these helpers skip and say why.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.support.wait import wait_for

CHROMIUM = os.environ.get("DELTADASH_CHROMIUM", "/usr/bin/chromium")
ARTIFACTS = Path(__file__).resolve().parents[2] / "artifacts"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    # WebGL without a GPU: chromium's software rasteriser (SwiftShader) must be allowed.
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]
# Software WebGL on a loaded 2-core machine can hold a page's main thread for tens of seconds
# at a time: a generous bound on waiting for the page, not a timing assertion.
PAGE_WAIT_S = 150.0
_TRY_MS = 5_000  # one try of a Playwright wait inside a longer, condition-based wait


def browser_skip_reason() -> str | None:
    """Why browser tests cannot run here, or None when they can."""
    if not Path(CHROMIUM).exists() and shutil.which("chromium") is None:
        return f"chromium not installed at {CHROMIUM} (make test installs it with apt as root)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "playwright is not installed (pip install -e '.[test]')"
    return None


def require_browser() -> None:
    """Skip the calling test with the reason when no browser can be driven."""
    reason = browser_skip_reason()
    if reason is not None:
        pytest.skip(reason)


@contextmanager
def chromium_page(width: int = 1280, height: int = 800) -> Iterator[Any]:
    """A Playwright page in headless chromium with a fresh profile, closed afterwards."""
    require_browser()
    from playwright.sync_api import sync_playwright

    executable = CHROMIUM if Path(CHROMIUM).exists() else shutil.which("chromium")
    with (
        tempfile.TemporaryDirectory(prefix="deltadash-chromium-") as profile,
        sync_playwright() as playwright,
    ):
        context = playwright.chromium.launch_persistent_context(
            profile,
            executable_path=executable,
            headless=True,
            args=CHROMIUM_ARGS,
            viewport={"width": width, "height": height},
        )
        try:
            yield context.pages[0] if context.pages else context.new_page()
        finally:
            context.close()


# The page tests' servers: the simulator's process, starved on a loaded 2-core machine
# with chromium beside it, can stand still past the 0.5 s stale-feedback limit, or lag its
# command past the following-error limit for over 0.5 s, and fault a move or a run
# half-way (tests/control/ tests those faults); what the page tests look at is the page,
# so their simulator may stall or lag for up to 5 s.
PATIENT_SIM_ENV = {
    "DELTADASH_SAFETY__STALE_FEEDBACK_S": "5",
    "DELTADASH_SAFETY__FOLLOWING_ERROR_TIME_S": "5",
}
SCENE_STUB = "<p style='font: 14px sans-serif'>3D scene (viser): stubbed in this test</p>"
# Every message the page showed, in order (window.__toasts), for a timed-out wait to print.
RECORD_TOASTS = """
document.addEventListener("DOMContentLoaded", () => {
  const toast = document.getElementById("toast");
  if (!toast) return;
  window.__toasts = [];
  new MutationObserver(() => {
    const said = toast.textContent;
    if (said && window.__toasts[window.__toasts.length - 1] !== said) window.__toasts.push(said);
  }).observe(toast, { childList: true, characterData: true, subtree: true });
});
"""


def toasts(page: Any) -> list[str]:
    """The messages the page has shown so far (dashboard_page records them)."""
    try:
        return page.evaluate("window.__toasts || []")
    except Exception as exc:  # a page mid-navigation: say so rather than fail the report
        return [f"unreadable: {exc}"]


@contextmanager
def dashboard_page(
    server: Any,
    width: int = 1366,
    height: int = 900,
    *,
    stub_scene: bool = True,
    on_page: Any = None,
) -> Iterator[Any]:
    """The dashboard of ``server`` (a tests.support.server.Server) in a fresh chromium page,
    asserting afterwards that no JavaScript error happened on it.

    ``stub_scene``: the embedded 3D scene is answered with a short note under any host name
    (the page embeds it under the other one of localhost / 127.0.0.1): its software WebGL
    would take a core from the test; the scene has its own tests. ``on_page(page)`` runs
    before the page loads (e.g. to listen to its requests). Loading waits only for the
    first bytes: a loaded machine can take longer than Playwright's 30 s to fire "load",
    so tests wait on the conditions they need.
    """
    with chromium_page(width, height) as page:
        errors: list[str] = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        if stub_scene:
            scene = f"http://*:{server.get('/api/info')['viser_port']}/**"
            page.route(
                scene, lambda route: route.fulfill(content_type="text/html", body=SCENE_STUB)
            )
        page.add_init_script(RECORD_TOASTS)
        if on_page is not None:
            on_page(page)
        page.goto(server.url + "/", wait_until="commit", timeout=PAGE_WAIT_S * 1e3)
        yield page
        assert not errors, f"JavaScript errors on the page: {errors}"


def plots_frame(page: Any, timeout_s: float = PAGE_WAIT_S) -> Any:
    """The dashboard's tracking plots: the Playwright frame of plots.html (which the page loads
    from the other loopback name, its own renderer process) once its plots module has run,
    scrolled into view (chromium draws no frame of another site while it is off screen).
    Look it up again after a reload: the frame is a new one then."""

    def found() -> Any:
        page.evaluate("0")  # a new frame is known only after a call into Playwright
        frame = next((f for f in page.frames if "/plots.html" in f.url), None)
        if frame is None:
            return None
        try:
            return frame if frame.evaluate("Boolean(window.deltadashPlot)") else None
        except Exception:  # navigating, or its document not there yet
            return None

    frame = wait_for(found, "the tracking plots' frame", timeout_s, poll_s=0.2)
    frame.frame_element().evaluate("e => e.scrollIntoView({block: 'nearest'})")
    return frame


def frame_pixel(frame: Any, x: float, y: float) -> tuple[float, float]:
    """The page pixel of ``(x, y)`` in ``frame``'s viewport (for page.mouse)."""
    box = frame.frame_element().bounding_box()
    return box["x"] + x, box["y"] + y


def box_of(locator: Any, what: str, timeout_s: float = PAGE_WAIT_S) -> dict[str, float]:
    """The bounding box of ``locator`` once it is laid out with a size; fail naming ``what``.

    Playwright's own ``bounding_box()`` gives up after one 30 s timeout, which a page
    rendering WebGL in software can spend busy: retry in short tries up to the deadline.
    """
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    last = "nothing yet"

    def laid_out() -> dict[str, float] | None:
        nonlocal last
        try:
            box = locator.bounding_box(timeout=_TRY_MS)
        except PlaywrightTimeout:
            last = f"not on the page within a {_TRY_MS / 1e3:g} s try"
            return None
        last = f"bounding box {box}"
        return box if box is not None and box["width"] > 0 and box["height"] > 0 else None

    return wait_for(
        laid_out, f"{what} laid out on the page", timeout_s, poll_s=0.5, seen=lambda: last
    )


def page_condition(page: Any, script: str, what: str, timeout_s: float = PAGE_WAIT_S) -> None:
    """Wait until the JavaScript ``script`` (a function expression) returns true in ``page``;
    fail naming ``what`` instead of Playwright's bare "Timeout exceeded"."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    try:
        page.wait_for_function(script, timeout=timeout_s * 1e3)
    except PlaywrightTimeout:
        raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}") from None


def save_artifact(name: str, data: bytes) -> Path:
    """Write ``data`` under artifacts/ (git-ignored) and return the path."""
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / name
    path.write_bytes(data)
    return path

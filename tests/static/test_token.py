"""With a token configured, the page asks for it once and then controls and streams."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.support.browser import browser_skip_reason, chromium_page, plots_frame
from tests.support.server import Server, serve, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
TOKEN = "dashboard-test-token"


@pytest.fixture(scope="module")
def token_server(tmp_path_factory) -> Iterator[Server]:
    folder = tmp_path_factory.mktemp("dashboard-token")
    with serve(folder, DELTADASH_SERVER__TOKEN=TOKEN) as server:  # no scene: the page says so
        yield server


def test_token_prompt_then_control_and_telemetry(token_server: Server) -> None:
    prompts: list[str] = []

    def answer(dialog: Any) -> None:
        prompts.append(dialog.message)
        dialog.accept(TOKEN)

    with chromium_page(1280, 800) as page:
        page.on("dialog", answer)
        page.goto(token_server.url + "/")
        # the telemetry stream is refused without the token: the page asks, then connects
        plots = plots_frame(page)  # the plots' frame: its stream was refused, the page asked
        wait_for(lambda: plots.evaluate("window.deltadashPlot.connected"), "telemetry with token")
        assert page.evaluate("sessionStorage.getItem('deltadash.token')") == TOKEN
        wait_for(  # clicked until accepted (an arm past its joint limits is refused)
            lambda: token_server.get("/api/status")["torque"] or page.click("#torque-on"),
            "torque on with the token",
        )
        assert len(prompts) == 1, prompts
        assert "turned off" in page.locator("#scene-note").inner_text()  # server.scene = false
